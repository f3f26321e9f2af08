"""CANopen CiA 402 drive profile on top of python ``canopen``'s LocalNode.

``canopen`` gives the object dictionary (from ``bus_config/cia402_drive.eds``),
the SDO server, NMT slave with boot-up and heartbeat, the EMCY producer and
PDO maps. It does not answer SYNC with TPDOs, does not tie PDO contents to
the object dictionary, and implements no 402 device (canopen issues #555,
#558, #166): those parts are written here, the ones that need no CAN (power
state machine, statusword, live objects) in :mod:`hil.drives.cia402_state`.

Threading: canopen calls back from python-can's Notifier thread. Every
callback takes the ``lock`` the owner passes in, the same lock the owner
holds while stepping the physics, so a drive never sees a half-done step.
At every SYNC the drive takes its latched setpoints, samples the state its
TPDOs will carry and reports the cycle's command (:class:`DriveProfile`'s
contract); the owner sends the TPDOs at once, or in lock-step after the
step, so the reply carries the state at SYNC and arrives only once the step
is done.
"""

from __future__ import annotations

import functools
import logging
import math
import struct
import time
from collections.abc import Callable
from contextlib import AbstractContextManager
from dataclasses import dataclass, replace
from pathlib import Path

import canopen
from canopen.sdo import SdoAbortedError

from hil.drives.cia402_state import (ERROR_REGISTER, LIVE_OBJECTS, MODE_CODES,
                                     Cia402StateMachine, int32, live_value, live_values,
                                     uint32)
from hil.drives.core import DriveCore, Power
from hil.drives.profile import DriveProfile

log = logging.getLogger(__name__)

EDS_PATH = Path(__file__).resolve().parents[2] / "bus_config" / "cia402_drive.eds"

SYNC_ID = 0x080
NMT_ID = 0x000
OPERATIONAL = "OPERATIONAL"

#: EMCY codes that are not drive faults (CiA 301).
EMCY_PDO_LENGTH = 0x8210
EMCY_SYNC_LENGTH = 0x8240
EMCY_NO_ERROR = 0x0000


@dataclass(frozen=True)
class PdoLayout:
    """A PDO mapping compiled to one struct. canopen packs and unpacks a PDO variable by
    variable through the object dictionary (about 30 us a PDO here), too slow for the
    per-SYNC path of six drives; its PdoMap stays the source of the mapping."""

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


class Cia402Drive(DriveProfile):
    """A CiA 402 servo drive on a CANopen network, around a :class:`DriveCore`."""

    protocol = "cia402"
    uses_sync = True

    def __init__(self, node_id: int, core: DriveCore, lock: AbstractContextManager,
                 rated_torque: float, heartbeat_period: float = 0.1, options=None,
                 eds: Path = EDS_PATH):
        super().__init__(node_id, core, lock)
        self.rated_torque = rated_torque
        heartbeat_ms = round(heartbeat_period * 1000)
        self.machine = Cia402StateMachine(core)
        self.node = canopen.LocalNode(node_id, str(eds))
        self._heartbeat_ms = heartbeat_ms
        self._latched: dict[int, bytes] = {}
        self._fault_reported = False
        self._pending: list[tuple[int, bytes]] = []
        # from the PDO maps at each (re)configuration: RPDO number -> layout, and the
        # synchronous TPDOs, each with its struct and the LIVE_OBJECTS it carries (None
        # and (): packed by canopen, see PdoLayout.of, or it maps a stored object)
        self._rpdo_layouts: dict[int, PdoLayout | None] = {}
        self._rpdo_handlers: list[tuple[int, Callable]] = []     # (COB-ID, subscribed)
        self._sync_tpdos: list[tuple[object, struct.Struct | None, tuple[int, ...]]] = []
        self._counts_per_rad = core.parameters.counts_per_rev / (2 * math.pi)
        self._store_configuration()
        self.node.add_read_callback(self._on_read)
        self.node.add_write_callback(self._on_write)

    # --- network life cycle ---------------------------------------------------

    @classmethod
    def bus_frames(cls, node_id: int, cycle_hz: float, heartbeat_period: float, options=None
                   ) -> list[tuple[int, int, float]]:
        """(arbitration id, payload bytes, frames/s) of the default mapping's exchange:
        RPDO1 (controlword, target), TPDO1, TPDO2 per SYNC; heartbeat; EMCY and SDO
        only on events (their ids are reserved)."""
        return [(0x200 + node_id, 6, cycle_hz), (0x180 + node_id, 6, cycle_hz),
                (0x280 + node_id, 6, cycle_hz), (0x700 + node_id, 1, 1.0 / heartbeat_period),
                (0x080 + node_id, 8, 0.0), (0x580 + node_id, 8, 0.0), (0x600 + node_id, 8, 0.0)]

    def subscriptions(self):
        return {NMT_ID: self._after_nmt, SYNC_ID: self._on_sync}

    def attach(self, network: canopen.Network) -> None:
        """Join the network: PDO maps from the object dictionary, boot-up, heartbeat."""
        network.add_node(self.node)
        super().attach(network)
        self._configure_pdos()
        self._boot()

    def detach(self) -> None:
        if not self.attached:
            return
        network = self.network
        self.node.nmt.stop_heartbeat()
        super().detach()
        self._unsubscribe_rpdos(network)
        self.node.remove_network()

    @property
    def state_text(self) -> str:
        return f"{self.node.nmt.state} {self.machine.state.name}"

    def _boot(self) -> None:
        """Boot-up message, pre-operational, heartbeat (CiA 301 initialisation)."""
        self.node.nmt.send_command(0x81)   # reset node: state 0, sends the boot-up frame
        self.node.nmt.send_command(0x80)   # enter pre-operational: starts the heartbeat

    def _after_nmt(self, can_id: int, data: bytes, timestamp: float) -> None:
        """Runs after canopen's NMT slave has applied a command."""
        if len(data) != 2 or data[1] not in (0, self.node_id):
            return
        with self.lock:
            state = self.node.nmt.state
            if state == "INITIALISING":
                self._reset(communication_only=data[0] == 0x82)
            elif state == OPERATIONAL and data[0] == 0x01:
                self._configure_pdos()     # mappings written by SDO take effect on start
            elif state != OPERATIONAL and self.core.power is Power.ENABLED:
                # leaving OPERATIONAL while enabled: abort connection option 3 (quick stop)
                self.core.quick_stop()

    def _reset(self, communication_only: bool) -> None:
        if not communication_only:
            self.machine.controlword(0x0000)
            self.core.reset_fault()
            self.node.data_store.clear()
            self._store_configuration()
        self._configure_pdos()
        self._latched.clear()
        self._boot()

    def _configure_pdos(self) -> None:
        network = self.node.network
        self._unsubscribe_rpdos(network)
        self.node.tpdo.read()
        self.node.rpdo.read()
        # read() subscribed canopen's PdoMap.on_message, which takes a Condition and
        # notifies its waiters on every frame (a drive has none): RPDOs come straight here
        for number, pdo in self.node.rpdo.map.items():
            if pdo.enabled:
                network.unsubscribe(pdo.cob_id, pdo.on_message)
                handler = functools.partial(self._on_rpdo, number)
                network.subscribe(pdo.cob_id, handler)
                self._rpdo_handlers.append((pdo.cob_id, handler))
        self._rpdo_layouts = {number: PdoLayout.of(pdo)
                              for number, pdo in self.node.rpdo.map.items()}
        self._sync_tpdos = []
        for pdo in self.node.tpdo.map.values():
            if pdo.enabled and pdo.trans_type is not None and 1 <= pdo.trans_type <= 240:
                layout = PdoLayout.of(pdo)
                if layout is not None and LIVE_OBJECTS >= set(layout.indices):
                    self._sync_tpdos.append((pdo, layout.codec, layout.indices))
                else:
                    self._sync_tpdos.append((pdo, None, ()))

    # --- cyclic exchange --------------------------------------------------------

    def _unsubscribe_rpdos(self, network: canopen.Network) -> None:
        for cob_id, handler in self._rpdo_handlers:
            if handler in network.subscribers.get(cob_id, []):
                network.unsubscribe(cob_id, handler)
        self._rpdo_handlers = []

    def _on_rpdo(self, number: int, can_id: int, data: bytes, timestamp: float) -> None:
        pdo = self.node.rpdo.map[number]
        expected = math.ceil(pdo.length / 8)
        if len(data) != expected:
            self.node.emcy.send(EMCY_PDO_LENGTH, 0x11,
                                struct.pack("<HB", len(data), expected) + b"\0\0")
            return
        if self.node.nmt.state != OPERATIONAL:
            return
        with self.lock:
            self._latched[number] = bytes(data)
            self.core.new_setpoint(now=time.monotonic())
            if pdo.trans_type is not None and pdo.trans_type >= 254:
                self._apply(number)

    def _on_sync(self, can_id: int, data: bytes, timestamp: float) -> None:
        with self.lock:
            self.sync_receive(data)
            self.prepare_tpdos()
            self.on_command(self)

    def sync_receive(self, data: bytes) -> None:
        """SYNC: take the latched setpoints (caller holds the lock)."""
        if len(data) > 1:
            self.node.emcy.send(EMCY_SYNC_LENGTH, 0x11)
            return
        if self.node.nmt.state != OPERATIONAL:
            return
        for number in sorted(self._latched):
            self._apply(number)
        self._latched.clear()

    def prepare_tpdos(self) -> None:
        """SYNC: pack the synchronous TPDOs with the current state (caller holds the lock)."""
        self._pending = []
        if self.node.nmt.state != OPERATIONAL:
            return
        status, state = self.core.status(), self.machine.state
        for pdo, codec, indices in self._sync_tpdos:
            if codec is not None:
                self._pending.append((pdo.cob_id, codec.pack(*live_values(
                    indices, state, status, self._counts_per_rad, self.rated_torque))))
                continue
            for variable in pdo.map:     # through the object dictionary, live or stored
                variable.set_data(self.node.get_data(variable.index, variable.subindex))
            self._pending.append((pdo.cob_id, bytes(pdo.data)))

    def send_replies(self) -> None:
        """Send the TPDOs :meth:`prepare_tpdos` packed."""
        pending, self._pending = self._pending, []
        for cob_id, data in pending:
            self.send(cob_id, data)

    def _apply(self, number: int) -> None:
        pdo = self.node.rpdo.map[number]
        pdo.data = self._latched.get(number, pdo.data)
        layout = self._rpdo_layouts.get(number)
        if layout is not None:
            fields = dict(zip(layout.indices, layout.codec.unpack(pdo.data)))
        else:
            fields = {variable.index: variable.raw for variable in pdo.map}
        if 0x6040 in fields:
            self.machine.controlword(fields[0x6040])
        if 0x6060 in fields:
            self._set_mode(fields[0x6060])
        self.core.new_setpoint(
            position=fields[0x607A] / self._counts_per_rad if 0x607A in fields else None,
            velocity=fields[0x60FF] / self._counts_per_rad if 0x60FF in fields else None,
            torque=fields[0x6071] * self.rated_torque / 1000 if 0x6071 in fields else None)

    def after_update(self) -> None:
        """After the inner loops ran: state machine follow-ups and EMCY for new faults."""
        self.machine.after_update()
        events, self.core.events = self.core.events, []
        if not self.attached:
            return
        for fault in events:
            self.node.emcy.send(fault.code, ERROR_REGISTER[fault])
        if self._fault_reported and self.core.fault is None:
            self.node.emcy.send(EMCY_NO_ERROR, 0)       # error reset
        self._fault_reported = self.core.fault is not None

    # --- object dictionary ---------------------------------------------------------

    def _on_read(self, index: int, subindex: int, od) -> int | None:
        if index in LIVE_OBJECTS:
            with self.lock:
                return live_value(index, self.machine.state, self.core.status(),
                                  self._counts_per_rad, self.rated_torque)
        return None

    def _on_write(self, index: int, subindex: int, od, data: bytes) -> None:
        value = od.decode_raw(data)
        with self.lock:
            if index == 0x6040:
                self.machine.controlword(value)
            elif index == 0x6060:
                self._set_mode(value)
            elif index == 0x605A:
                if value not in (1, 2, 5, 6):
                    raise SdoAbortedError(0x06090030)
                self.machine.quick_stop_option = value
            elif index in _PARAMETER_WRITERS:
                self.core.parameters = _PARAMETER_WRITERS[index](
                    self.core.parameters, subindex, value, self._counts_per_rad)

    def _set_mode(self, code: int) -> None:
        if code not in MODE_CODES:
            raise SdoAbortedError(0x06090030)   # value range of parameter exceeded
        self.core.set_mode(MODE_CODES[code])

    def _store_configuration(self) -> None:
        """Write the drive's configured values into its object dictionary."""
        p = self.core.parameters
        cpr = self._counts_per_rad
        store = self.node.data_store
        od = self.node.object_dictionary

        def put(index, subindex, value):
            entry = od[index] if subindex is None else od[index][subindex]
            store.setdefault(index, {})[subindex or 0] = entry.encode_raw(value)

        put(0x1017, None, self._heartbeat_ms)
        put(0x6076, None, round(self.rated_torque * 1000))
        put(0x6072, None, round(p.peak_torque / self.rated_torque * 1000))
        put(0x608F, 1, p.counts_per_rev)
        put(0x607F, None, uint32(p.max_velocity * cpr))
        put(0x6085, None, uint32(p.quick_stop_deceleration * cpr))
        put(0x6065, None, uint32(p.following_error_limit * cpr))
        put(0x6066, None, round(p.following_error_timeout * 1000))
        put(0x2010, None, round(p.watchdog_timeout * 1000))
        put(0x2000, 1, p.position_kp)
        put(0x2000, 2, p.velocity_kp)
        put(0x2000, 3, p.velocity_ki)
        if p.position_limits is not None:
            put(0x607D, 1, int32(p.position_limits[0] * cpr))
            put(0x607D, 2, int32(p.position_limits[1] * cpr))


def _gains(p, subindex, value, cpr):
    name = {1: "position_kp", 2: "velocity_kp", 3: "velocity_ki"}.get(subindex)
    return replace(p, **{name: float(value)}) if name else p


def _limits(p, subindex, value, cpr):
    low, high = p.position_limits or (-math.inf, math.inf)
    if subindex == 1:
        low = value / cpr
    elif subindex == 2:
        high = value / cpr
    return replace(p, position_limits=(low, high))


#: SDO-writable parameters that take effect at once: index -> (parameters, sub, value, counts/rad)
_PARAMETER_WRITERS = {
    0x2000: _gains,
    0x2010: lambda p, s, v, c: replace(p, watchdog_timeout=v / 1000),
    0x6065: lambda p, s, v, c: replace(p, following_error_limit=v / c),
    0x6066: lambda p, s, v, c: replace(p, following_error_timeout=v / 1000),
    0x6085: lambda p, s, v, c: replace(p, quick_stop_deceleration=v / c),
    0x607D: _limits,
}
