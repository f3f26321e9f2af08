"""The simulated drive's PDOs as data: a mapping compiled to one struct, and when each TPDO
goes out."""

from __future__ import annotations

import math
import struct
from dataclasses import dataclass, field
from typing import Any

from hil.protocols.cia402.eds import LIVE_OBJECTS
from hil.protocols.cia402.network import extended_cob_id
from hil.protocols.cia402.objects import PROFILE_PARAMETERS


@dataclass(frozen=True)
class PdoLayout:
    """A PDO mapping compiled to one struct. canopen packs and unpacks a PDO variable by
    variable through the object dictionary (docs/performance.md, "2026-12-06, later:
    figures from code comments"), too slow for the per-SYNC path of six drives; its PdoMap
    stays the source of the mapping."""

    indices: tuple[int, ...]
    codec: struct.Struct

    @classmethod
    def of(cls, pdo) -> PdoLayout | None:
        """The layout of a canopen PdoMap, or None where a mapped object is not a whole-byte
        number in its place (canopen's own packing then does it)."""
        formats, offset = [], 0
        for variable in pdo.map:
            kind = variable.od.STRUCT_TYPES.get(variable.od.data_type)
            if kind is None or variable.offset != offset or variable.length != 8 * kind.size:
                return None
            formats.append(kind.format.lstrip("<"))
            offset += variable.length
        return cls(tuple(variable.index for variable in pdo.map),
                   struct.Struct("<" + "".join(formats)))


@dataclass(frozen=True)
class Rpdo:
    """One RPDO as the drive takes it, read from canopen's PdoMap at each (re)configuration
    (the mapping and communication parameters take effect then, not frame by frame)."""

    pdo: Any                               # canopen PdoMap
    length: int                            # bytes its mapping fills
    immediate: bool                        # types 254, 255: applied on arrival, not at SYNC
    layout: PdoLayout | None
    profile: tuple[int, ...]               # the profile parameters it maps, in its order
    offsets: bool                          # maps a target velocity or a velocity/torque offset
    # what else it maps, asked at every apply: flags made once, not membership tests of
    # `at` (those cost a share of every cycle: docs/performance.md, "2026-12-06, later:
    # figures from code comments")
    mode: bool = False                     # modes of operation (0x6060)
    controlword: bool = False              # 0x6040
    targets: tuple[int, ...] = ()          # target positions mapped: 0x607A, 0x60C1
    torque: bool = False                   # target torque (0x6071)
    #: each mapped object's place in the mapping (an object mapped twice: its last place)
    at: dict[int, int] = field(default_factory=dict)

    @classmethod
    def of(cls, pdo) -> Rpdo:
        kind = pdo.trans_type
        indices = [variable.index for variable in pdo.map]
        return cls(pdo, math.ceil(pdo.length / 8), kind is not None and kind >= 254,
                   PdoLayout.of(pdo), tuple(i for i in indices if i in PROFILE_PARAMETERS),
                   any(i in indices for i in (0x60FF, 0x60B1, 0x60B2)),
                   0x6060 in indices, 0x6040 in indices,
                   tuple(i for i in (0x607A, 0x60C1) if i in indices), 0x6071 in indices,
                   {index: place for place, index in enumerate(indices)})


@dataclass
class TpdoSchedule:
    """When one TPDO goes out: its transmission type, event timer and inhibit time."""

    pdo: Any                               # canopen PdoMap
    codec: struct.Struct | None            # None: packed by canopen (PdoLayout.of)
    indices: tuple[int, ...]               # the LIVE_OBJECTS it carries (codec only)
    transmission_type: int
    event_timer: float = 0.0               # s; 0: none
    inhibit: float = 0.0                   # s
    syncs: int = 0                         # SYNCs since it last went out (types 1-240)
    last_data: bytes | None = None         # what it last sent (types 0, 254, 255)
    last_sent: float = field(default=-math.inf)
    rtr_allowed: bool = False              # COB-ID bit 30 clear
    start: int = 0                         # SYNC start value (sub-index 6; 0: none)
    running: bool = False                  # past its SYNC start value
    #: its COB-ID (the PdoMap's, kept at hand for every frame) and frame format
    cob_id: int = field(init=False)
    extended: bool = field(init=False)

    def __post_init__(self) -> None:
        self.cob_id = self.pdo.cob_id
        self.extended = extended_cob_id(self.cob_id)

    @property
    def event_driven(self) -> bool:
        return self.transmission_type >= 254

    def started(self, counter: int | None) -> bool:
        """Whether it counts SYNCs yet: from the SYNC whose counter is its start value, when
        SYNCs carry a counter and it has one."""
        if not self.running and (not self.start or counter is None or counter == self.start):
            self.running = True
        return self.running


def tpdo_schedules(node) -> list[TpdoSchedule]:
    """The schedules of a canopen LocalNode's TPDOs as its maps and communication parameters
    (0x1800+n: 3 inhibit time, 5 event timer, 6 SYNC start value) have them now: those
    valid and of a transmission type; packed from one struct where every object they map is
    a live one (hil.protocols.cia402.state), else by canopen."""
    schedules = []
    for number, pdo in node.tpdo.map.items():
        if not pdo.enabled or pdo.trans_type is None:
            continue
        layout = PdoLayout.of(pdo)
        if layout is not None and LIVE_OBJECTS >= set(layout.indices):
            codec, indices = layout.codec, layout.indices
        else:
            codec, indices = None, ()
        communication = 0x1800 + number - 1
        schedules.append(TpdoSchedule(
            pdo, codec, indices, pdo.trans_type, node.value(communication, 5) / 1000.0,
            node.value(communication, 3) / 10000.0, rtr_allowed=pdo.rtr_allowed,
            start=node.value(communication, 6)))
    return schedules
