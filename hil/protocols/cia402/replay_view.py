"""What a replay compares of a CiA 402 drive's frames (:class:`DriveProfile`'s replay
contract): which frames are timed, and a TPDO's live objects as readings."""

from __future__ import annotations

import canopen

from hil.can.frame import Frame
from hil.drives.profile import Reading
from hil.protocols.cia402.node import DriveNode
from hil.protocols.cia402.objects import DriveObjects
from hil.protocols.cia402.tpdo import TpdoSet

#: the heartbeat's NMT state codes (CiA 301)
NMT_CODES = {name: code for code, name in canopen.nmt.NMT_STATES.items()}
#: what each live object measures (hil.drives.profile.QUANTITIES; None: exact), by index
MEASURES = {0x6064: "position", 0x60F4: "position", 0x606C: "velocity", 0x6077: "torque"}
#: statusword bits the drive sets from what it measures (target reached, internal limit
#: active, following error): they flip with the timing of a run
MEASURED_STATUS = 0x2C00


class ReplayView:
    """The replay contract of one :class:`hil.protocols.cia402.drive.Cia402Drive` over its
    node (its id and NMT state), its TPDOs as mapped now and its objects' units; the drive
    makes a new one with each new TPDO set."""

    def __init__(self, node: DriveNode, tpdos: TpdoSet, objects: DriveObjects,
                 rated_torque: float):
        self._node, self._tpdos, self._objects = node, tpdos, objects
        self._rated_torque = rated_torque

    @property
    def heartbeat_id(self) -> int:
        return 0x700 + self._node.id

    def timed(self, frame: Frame) -> bool:
        """The heartbeat (not the boot-up, which answers a reset) and event-driven TPDOs."""
        if frame.identifier == self.heartbeat_id:
            return frame.data[:1] != b"\x00"
        return any(s.event_driven and s.cob_id == frame.identifier
                   for s in self._tpdos.schedules)

    def timed_ids(self) -> tuple[int, ...]:
        return (self.heartbeat_id,)

    def timed_content(self, identifier: int) -> bytes | None:
        if identifier == self.heartbeat_id:
            return bytes([NMT_CODES[self._node.nmt.state]])
        return None

    def readings(self, frame: Frame) -> tuple[Reading, ...] | None:
        """A TPDO's live objects (as mapped now): positions and velocities in counts,
        torque in per mille of the rated torque, the rest exact."""
        for schedule in self._tpdos.schedules:
            if schedule.cob_id != frame.identifier or schedule.codec is None:
                continue
            if len(frame.data) != schedule.codec.size:
                return None
            scales = {"position": 1 / self._objects.counts_per_rad,
                      "velocity": 1 / self._objects.velocity_per_rad,
                      "torque": self._rated_torque / 1000}
            found = []
            for index, value in zip(schedule.indices, schedule.codec.unpack(frame.data)):
                if index == 0x6041:      # the state exact; what the position loop sets, derived
                    found += [Reading("0x6041", value & ~MEASURED_STATUS, None),
                              Reading("0x6041 bits 10, 11, 13", value & MEASURED_STATUS,
                                      "derived")]
                else:
                    found.append(Reading(f"0x{index:04X}", value, MEASURES.get(index),
                                         scales.get(MEASURES.get(index), 1.0)))
            return tuple(found)
        return None
