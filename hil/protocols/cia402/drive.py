"""A simulated CiA 402 servo drive on top of python ``canopen``'s LocalNode.

``canopen`` gives the object dictionary (from the EDS hil ships), the SDO server, NMT slave
with boot-up and heartbeat, the EMCY producer and PDO maps; :mod:`.node` makes that node
refuse what a real CiA 301 slave refuses. canopen does not answer SYNC with TPDOs, does not
tie PDO contents to the object dictionary, and implements no 402 device (canopen issues
#555, #558, #166): those parts are written here, the ones that need no CAN (power state
machine, operation modes' controlword bits, statusword, live objects) in :mod:`.state`,
the object dictionary's contents and SDO writes in :mod:`.objects`.

PDOs: RPDOs are processed in OPERATIONAL only; a synchronous one (transmission type
0-240) is latched and applied at the next SYNC, an event-driven one (254, 255) at once.
One shorter than its mapping is dropped with EMCY 0x8210, a longer one applied with EMCY
0x8220 (CiA 301). TPDOs of type 1-240 go out at every n-th SYNC, type 0 at a SYNC after
a mapped value changed, types 254/255 on a change (not sooner than the inhibit time) and
at least every event-timer period, checked every ``hil.simulator.WATCHDOG_PERIOD``.

The master's silence (the setpoint watchdog, a lost heartbeat of a producer in 0x1016, the
network leaving OPERATIONAL) gets the reaction 0x6007 selects (0 none, 1 fault, 2 disable
voltage, 3 quick stop).

Threading: canopen calls back from python-can's Notifier thread (or the bus' own
delivering thread); every callback takes the ``lock`` the owner holds while stepping the
physics. At every SYNC the drive takes its latched setpoints, samples the state its TPDOs
will carry and reports the cycle's command (:class:`DriveProfile`'s contract); the owner
sends the TPDOs at once, or in lock-step after the step.

LSS (:mod:`.lss`): a drive of node id 255 listens for LSS only until a master assigns one.
"""

from __future__ import annotations

import functools
import logging
import struct
import time
from collections.abc import Callable
from contextlib import AbstractContextManager

import canopen

from hil.drives.core import DriveCore
from hil.drives.definitions import Fault, Power
from hil.drives.profile import DriveProfile
from hil.protocols.cia402 import (LSS_ANSWER_ID, LSS_REQUEST_ID, NMT_ID, SYNC_ID, UNCONFIGURED,
                                  Cia402)
from hil.protocols.cia402.errors import (COMMUNICATION_ERROR, EMCY_NO_ERROR, EMCY_PDO_LENGTH,
                                         EMCY_PDO_LENGTH_EXCEEDED, EMCY_SYNC_LENGTH, PDO_ERRORS,
                                         ErrorRecord)
from hil.protocols.cia402.lss import Identity, LssSlave
from hil.protocols.cia402.node import DriveNode
from hil.protocols.cia402.objects import DriveObjects
from hil.protocols.cia402.pdo import PdoLayout, Rpdo, TpdoSchedule
from hil.protocols.cia402.personality import Personality
from hil.protocols.cia402.replay_view import ReplayView
from hil.protocols.cia402.storage import ParameterStore
from hil.protocols.cia402.tpdo import TpdoProducer
from hil.protocols.cia402.eds import LIVE_OBJECTS
from hil.protocols.cia402.state import (ERROR_REGISTER, INTERPOLATED_POSITION,
                                        Cia402StateMachine)

log = logging.getLogger(__name__)

OPERATIONAL, STOPPED = "OPERATIONAL", "STOPPED"
SYNC_COUNTER_OVERFLOW = 0x1019

#: a refused frame is logged the first time, then every this many
LOG_REFUSED_EVERY = 1000


class Cia402Drive(TpdoProducer, ReplayView, DriveProfile):
    """A CiA 402 servo drive on a CANopen network, around a :class:`DriveCore`."""

    protocol = Cia402

    def __init__(self, node_id: int, core: DriveCore, lock: AbstractContextManager,
                 rated_torque: float, heartbeat_period: float = 0.1, options=None):
        super().__init__(node_id, core, lock)
        self.rated_torque = rated_torque
        heartbeat_ms = round(heartbeat_period * 1000)
        self.machine = Cia402StateMachine(core)
        self.personality = Personality.of(options.eds if options is not None else None)
        self._serial = options.serial_number if options is not None else None
        self.store = ParameterStore(options.parameter_file if options is not None else None)
        self._heartbeat_ms = heartbeat_ms
        self._latched: dict[int, bytes] = {}
        self.errors = ErrorRecord()
        self._pending: list[tuple[int, bytes]] = []
        # from the PDO maps at each (re)configuration: the RPDOs by number, and the TPDOs
        # with their schedules
        self._rpdos: dict[int, Rpdo] = {}
        self._rpdo_handlers: list[tuple[int, Callable]] = []     # (COB-ID, subscribed)
        self._tpdos: list[TpdoSchedule] = []
        self._remote_ids: list[int] = []        # TPDO COB-IDs that answer an RTR
        self._last_tick = time.monotonic()
        #: the bus config's parameters: the application area's values after a reset node
        self._configured = (core.parameters, core.silence_reaction)
        self._make_node(node_id)
        self.lss = LssSlave(Identity(*(self.node.value(0x1018, sub) for sub in range(1, 5))),
                            node_id, lambda data: self.send(LSS_ANSWER_ID, data),
                            self._take_node_id)

    @property
    def _counts_per_rad(self) -> float:
        return self.objects.counts_per_rad

    def _make_node(self, node_id: int) -> None:
        """The CANopen node of ``node_id`` (UNCONFIGURED: one that waits for LSS)."""
        self.node_id = node_id
        self.node = DriveNode(node_id, self.personality.dictionary(node_id), self._refused)
        self.objects = DriveObjects(self.node, self.machine, self.core, self.lock,
                                    self.rated_torque, self._heartbeat_ms, self._configure_pdos,
                                    self.errors, self.personality, self._serial, self.store)
        self.objects.store_configuration()
        self._restore(communication_only=False)
        self.node.on_stored(self._on_stored)
        self._refresh_sync_length()

    def _restore(self, communication_only: bool) -> None:
        for refused in self.store.restore(self.node, communication_only):
            log.warning("node %d: saved %s not restored from %s: save them again", self.node_id,
                        refused, self.store.file or "this run's store")

    def _on_stored(self, index: int, subindex: int) -> None:
        if index == SYNC_COUNTER_OVERFLOW:
            self._refresh_sync_length()

    def _refresh_sync_length(self) -> None:
        """The SYNC's data length 0x1019 asks for (a counter where over 0), kept at hand for
        every SYNC (read from the dictionary it was 5 % of a lock-step cycle)."""
        self._sync_length = 1 if self.node.value(SYNC_COUNTER_OVERFLOW) else 0

    def _take_node_id(self, node_id: int) -> None:
        """LSS gave the drive a node id (CiA 305; caller holds the lock), a taken one too
        (CiA 305 refuses only one out of range): as on a real bus, both nodes then hear its NMT
        and SDO and send on its COB-IDs (``associate_network``: canopen's one-per-id
        ``add_node`` dropped the other node's network); a warning shows the collision."""
        network = self.network
        if network.subscribers.get(0x600 + node_id) and node_id != UNCONFIGURED:
            log.warning("node id %d given by LSS is another drive's too: both answer", node_id)
        if self.node.has_network():
            self.node.nmt.stop_heartbeat()
            self._unsubscribe_rpdos(network)
            self.node.remove_network()
        self._make_node(node_id)
        if node_id != UNCONFIGURED:
            self.node.associate_network(network)
            network.unsubscribe(NMT_ID, self._after_nmt)     # again after the node's NMT
            network.subscribe(NMT_ID, self._after_nmt)
            self._configure_pdos()
            self._boot()

    # --- network life cycle ---------------------------------------------------

    def subscriptions(self):
        return {NMT_ID: self._after_nmt, SYNC_ID: self._on_sync, LSS_REQUEST_ID: self._on_lss}

    def attach(self, network: canopen.Network) -> None:
        """Join the network: PDO maps from the object dictionary, boot-up, heartbeat (a
        drive without a node id only listens for LSS)."""
        if self.node_id != UNCONFIGURED:
            # its NMT slave before this drive's _after_nmt; not network.add_node (above)
            self.node.associate_network(network)
        super().attach(network)
        if self.node_id != UNCONFIGURED:
            self._configure_pdos()
            self._boot()

    def _on_lss(self, can_id: int, data: bytes, timestamp: float) -> None:
        with self.lock:
            self.lss.on_request(can_id, data, timestamp)

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

    def _refused(self, can_id: int, why: str) -> None:
        self.malformed += 1
        if self.malformed % LOG_REFUSED_EVERY == 1:
            log.warning("node %d refused frame 0x%03X: %s (%d so far)", self.node_id, can_id,
                        why, self.malformed)

    def _boot(self) -> None:
        """Boot-up message, pre-operational, heartbeat (CiA 301 initialisation)."""
        self.node.nmt.stop_heartbeat()      # no heartbeat of state 0 beside the boot-up
        self.node.nmt.send_command(0x81)   # reset node: state 0, sends the boot-up frame
        self.node.nmt.send_command(0x80)   # enter pre-operational: starts the heartbeat

    def _after_nmt(self, can_id: int, data: bytes, timestamp: float) -> None:
        """Runs after canopen's NMT slave has applied a command."""
        if len(data) != 2 or data[1] not in (0, self.node_id) or not self.node.has_network():
            return
        with self.lock:
            state = self.node.nmt.state
            if state == "INITIALISING" and self.lss.pending_node_id not in (self.node_id,
                                                                            UNCONFIGURED):
                self._take_node_id(self.lss.pending_node_id)   # CiA 305: at a reset
            elif state == "INITIALISING":
                self._reset(communication_only=data[0] == 0x82)
            elif state == OPERATIONAL and data[0] == 0x01:
                self._configure_pdos()     # mappings written by SDO take effect on start
            elif state != OPERATIONAL:
                self._latched.clear()
                self.core.lose_connection()     # 0x6007 says what leaving OPERATIONAL does
                self.machine.after_update()

    def restart(self) -> None:
        """A power cycle: the application reset (CiA 301 0x81), stored configuration and all,
        then boot-up in PRE-OPERATIONAL, with the node id LSS stored (CiA 305)."""
        stored = self.lss.power_on()
        if stored != self.node_id:
            self._take_node_id(stored)
        self._reset(communication_only=False)

    def _reset(self, communication_only: bool) -> None:
        self.errors.history.clear()              # 0x1003 is in the communication area
        if not communication_only:
            self.errors.active.clear()
            self.machine.error_register = 0
            # CiA 301 7.2.8.3.2.1: reset node sets the application area (and the rest) to
            # its power-on values: the config's, not what SDO writes made of them
            self.machine.controlword(0x0000)
            self.core.reset_fault()
            self.machine.reset_homing()
            self.core.parameters, self.core.silence_reaction = self._configured
            self.node.data_store.clear()
            self.objects.store_configuration()
        else:    # the communication area (0x1000-0x1FFF) takes its defaults again
            for index in [i for i in self.node.data_store if 0x1000 <= i < 0x2000]:
                del self.node.data_store[index]
            self.objects.store_communication()
        self._restore(communication_only)                    # what 0x1010 saved
        self._refresh_sync_length()
        self._latched.clear()
        if self.node.has_network():
            self.node.configure_heartbeat_consumers()
            self._configure_pdos()
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
        self._rpdos = {number: Rpdo.of(pdo) for number, pdo in self.node.rpdo.map.items()}
        self._tpdos = []
        for number, pdo in self.node.tpdo.map.items():
            if not pdo.enabled or pdo.trans_type is None:
                continue
            layout = PdoLayout.of(pdo)
            live = layout is not None and LIVE_OBJECTS >= set(layout.indices)
            communication = 0x1800 + number - 1
            self._tpdos.append(TpdoSchedule(
                pdo, layout.codec if live else None, layout.indices if live else (),
                pdo.trans_type, self.node.value(communication, 5) / 1000.0,
                self.node.value(communication, 3) / 10000.0, rtr_allowed=pdo.rtr_allowed,
                start=self.node.value(communication, 6)))
        self.serve_remote_requests(network)

    # --- cyclic exchange --------------------------------------------------------

    def _unsubscribe_rpdos(self, network: canopen.Network) -> None:
        for cob_id, handler in self._rpdo_handlers:
            if handler in network.subscribers.get(cob_id, []):
                network.unsubscribe(cob_id, handler)
        self._rpdo_handlers = []

    def _on_rpdo(self, number: int, can_id: int, data: bytes, timestamp: float) -> None:
        if not self.node.nmt.operational:
            return                            # PDOs are off outside OPERATIONAL (CiA 301)
        rpdo = self._rpdos[number]
        expected, size = rpdo.length, len(data)
        with self.lock:
            if size != expected:
                code = EMCY_PDO_LENGTH if size < expected else EMCY_PDO_LENGTH_EXCEEDED
                self._frame_error(code, struct.pack("<HB", size, expected) + b"\0\0")
                if size < expected:
                    return
                data = data[:expected]
            elif self.errors.active and self.errors.end(PDO_ERRORS):
                self._error_changed(EMCY_NO_ERROR)      # an RPDO of its length again
            self._latched[number] = bytes(data)
            self.core.new_setpoint(now=time.monotonic())
            if rpdo.immediate:
                self._apply(number)

    def _on_sync(self, can_id: int, data: bytes, timestamp: float) -> None:
        with self.lock:
            self.sync_receive(data)
            self.prepare_tpdos(data[0] if len(data) == 1 else None)
            self.on_command(self)

    def sync_receive(self, data: bytes) -> None:
        """SYNC: take the latched setpoints (caller holds the lock). A SYNC carries a
        counter where 0x1019 (its overflow value) is over 0, none otherwise (CiA 301)."""
        operational = self.node.nmt.operational
        if len(data) != self._sync_length:
            self._frame_error(EMCY_SYNC_LENGTH)
            return
        if self.errors.active and self.errors.end((EMCY_SYNC_LENGTH,)):
            self._error_changed(EMCY_NO_ERROR)          # a SYNC of its length again
        if not operational:
            return
        for number in sorted(self._latched):
            self._apply(number)
        self._latched.clear()

    def tick(self, now: float) -> None:
        """The heartbeat, event-driven TPDOs (254, 255) and the heartbeat consumer (caller
        holds the lock)."""
        self.node.sdo.expire(now)
        self.machine.ramp_torque(now - self._last_tick)
        self._last_tick = now
        beat = self.node.nmt.heartbeat_due(now)
        if beat is not None:
            self.send(0x700 + self.node_id, beat)
        for producer in self.node.lost_heartbeats(now):
            log.warning("node %d: the heartbeat of node %d stopped", self.node_id, producer)
            self.core.lose_connection(Fault.HEARTBEAT_LOST)
        if self.node.nmt.operational:
            self.send_event_tpdos(now)

    def _apply(self, number: int) -> None:
        rpdo = self._rpdos[number]
        pdo = rpdo.pdo
        data = pdo.data = self._latched.get(number, pdo.data)
        layout = rpdo.layout
        values = (layout.codec.unpack(data) if layout is not None
                  else [variable.raw for variable in pdo.map])
        at = rpdo.at            # each mapped object's place in values (no dict made a frame)
        objects, machine = self.objects, self.machine
        if rpdo.mode:
            objects.set_mode(values[at[0x6060]])
        for index in rpdo.profile:
            objects.set_profile_parameter(index, values[at[index]])
        # the controlword after the targets (profile position's new set-point takes the
        # target of its own PDO), but in ip mode before them: bit 4 gates its own PDO's record
        interpolated = machine.mode_code == INTERPOLATED_POSITION
        if rpdo.controlword and interpolated:
            machine.controlword(values[at[0x6040]])
        for index in rpdo.targets:      # objects.set_target_position's, a call less a frame
            machine.take_target_position(index, values[at[index]] / objects.counts_per_rad)
        if rpdo.torque:
            objects.set_target_torque(values[at[0x6071]])
        if rpdo.offsets:
            per_rad = objects.velocity_per_rad
            self.core.new_setpoint(
                velocity=values[at[0x60FF]] / per_rad if 0x60FF in at else None,
                velocity_ff=values[at[0x60B1]] / per_rad if 0x60B1 in at else None,
                torque_ff=values[at[0x60B2]] * self.rated_torque / 1000 if 0x60B2 in at
                else None)
        if rpdo.controlword and not interpolated:
            machine.controlword(values[at[0x6040]])

    def after_update(self) -> None:
        """After the inner loops ran: state machine follow-ups and EMCY for new faults."""
        # (called at every plant step: the common case, nothing new, asks no more)
        events = self.take_events() if self.machine.after_update() else ()
        if self.network is None:            # detached: silent
            return
        for fault in events:
            self.errors.enter(fault.code, ERROR_REGISTER[fault])
            self._error_changed(fault.code)
        if self.errors.active and self.errors.over(self.core.fault is not None,
                                                   self.core.power is Power.ENABLED):
            self.errors.end_drive_errors()
            self._error_changed(EMCY_NO_ERROR)

    def _frame_error(self, code: int, data: bytes = b"") -> None:
        """A frame the drive could not take: recorded and signalled (errors' module doc),
        except in STOPPED, where no EMCY goes out (CiA 301) and so none is recorded
        (caller holds the lock)."""
        if self.node.nmt.state == STOPPED:
            return
        self.errors.enter(code, COMMUNICATION_ERROR)
        self._error_changed(code, data)

    def _error_changed(self, code: int, data: bytes = b"") -> None:
        """0x1001 and 0x1003 as the error record has them, and the EMCY that says so."""
        self.machine.error_register = self.errors.register
        self.objects.store_errors()
        self.node.emcy.send(code, self.errors.register, data)
