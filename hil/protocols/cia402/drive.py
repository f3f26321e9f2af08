"""A simulated CiA 402 servo drive on top of python ``canopen``'s LocalNode.

``canopen`` gives the object dictionary (from the EDS hil ships), the SDO server, NMT slave
with boot-up and heartbeat, the EMCY producer and PDO maps; :mod:`.node` makes that node
refuse what a real CiA 301 slave refuses. canopen does not answer SYNC with TPDOs, does not
tie PDO contents to the object dictionary, and implements no 402 device (canopen issues
#555, #558, #166): those parts are written here, the ones that need no CAN (power state
machine, operation modes' controlword bits, statusword, live objects) in :mod:`.state`,
the object dictionary's contents and SDO writes in :mod:`.objects`, the PDOs' in
:mod:`.rpdo` and :mod:`.tpdo`. canopen's services hear and send through the bus' router
(:mod:`.network`); the PDOs and the SYNC, every cycle's frames, are the router's own
handlers here.

PDOs: RPDOs are processed in OPERATIONAL only; a synchronous one (transmission type
0-240) is latched and applied at the next SYNC, an event-driven one (254, 255) at once.
One shorter than its mapping is dropped with EMCY 0x8210, a longer one applied with EMCY
0x8220 (CiA 301). TPDOs of type 1-240 go out at every n-th SYNC, type 0 at a SYNC after
a mapped value changed, types 254/255 on a change (not sooner than the inhibit time) and
at least every event-timer period, checked every ``hil.simulator.WATCHDOG_PERIOD``.

The master's silence (the setpoint watchdog, a lost heartbeat of a producer in 0x1016, the
network leaving OPERATIONAL) gets the reaction 0x6007 selects (0 none, 1 fault, 2 disable
voltage, 3 quick stop).

Threading: the router calls back from python-can's Notifier thread (or the bus' own
delivering thread); every handler takes the ``lock`` the owner holds while stepping the
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
from contextlib import AbstractContextManager

from hil.bus_config.types import DriveConfig
from hil.can.frame import Frame
from hil.can.router import FrameRouter, Subscription
from hil.drives.core import DriveCore
from hil.drives.definitions import Fault, Power
from hil.drives.profile import DriveProfile, Reading
from hil.protocols.cia402 import (LSS_ANSWER_ID, LSS_REQUEST_ID, NMT_ID, SYNC_ID, UNCONFIGURED,
                                  Cia402)
from hil.protocols.cia402.emcy import ErrorSignals
from hil.protocols.cia402.errors import (EMCY_PDO_LENGTH, EMCY_PDO_LENGTH_EXCEEDED,
                                         EMCY_SYNC_LENGTH, PDO_ERRORS, ErrorRecord)
from hil.protocols.cia402.lss import Identity, LssSlave
from hil.protocols.cia402.network import RoutedNetwork, extended_cob_id
from hil.protocols.cia402.node import DriveNode
from hil.protocols.cia402.objects import DriveObjects
from hil.protocols.cia402.pdo import Rpdo, TpdoSchedule, tpdo_schedules
from hil.protocols.cia402.personality import Personality
from hil.protocols.cia402.replay_view import ReplayView
from hil.protocols.cia402.rpdo import RpdoSet
from hil.protocols.cia402.state import EMCY_CODES, Cia402StateMachine
from hil.protocols.cia402.storage import ParameterStore
from hil.protocols.cia402.tpdo import TpdoSet

log = logging.getLogger(__name__)

OPERATIONAL = "OPERATIONAL"
SYNC_COUNTER_OVERFLOW = 0x1019

#: a refused frame is logged the first time, then every this many
LOG_REFUSED_EVERY = 1000


class Cia402Drive(DriveProfile):
    """A CiA 402 servo drive on a CANopen network, around a :class:`DriveCore`."""

    protocol = Cia402
    follows_every_step = True       # quick stop's end, homing, a buffered set-point, EMCY

    def __init__(self, config: DriveConfig, core: DriveCore, lock: AbstractContextManager):
        super().__init__(config, core, lock)
        options = config.options
        self.rated_torque = config.rated_torque
        self.machine = Cia402StateMachine(core)
        self.personality = Personality.of(options.eds if options is not None else None)
        self._serial = options.serial_number if options is not None else None
        self.store = ParameterStore(options.parameter_file if options is not None else None)
        self._heartbeat_ms = round(config.heartbeat_period * 1000)
        self._latched: dict[int, bytes] = {}
        self.errors = ErrorRecord()
        #: canopen's network on the bus' router, while attached
        self._network: RoutedNetwork | None = None
        #: the router's handlers of the PDOs as configured (RPDOs; TPDOs' RTRs)
        self._pdo_subscriptions: list[Subscription] = []
        self._last_tick = time.monotonic()
        #: the bus config's parameters: the application area's values after a reset node
        self._configured = (core.parameters, core.silence_reaction)
        self._make_node(self.node_id)
        self.lss = LssSlave(Identity(*(self.node.value(0x1018, sub) for sub in range(1, 5))),
                            self.node_id, lambda data: self.send(Frame(LSS_ANSWER_ID, data)),
                            self._take_node_id)

    def _make_node(self, node_id: int) -> None:
        """The CANopen node of ``node_id`` (UNCONFIGURED: one that waits for LSS), its PDOs
        not configured yet."""
        self.node_id = node_id
        self.node = DriveNode(node_id, self.personality.dictionary(node_id), self._refused)
        self.objects = DriveObjects(self.node, self.machine, self.core, self.lock,
                                    self.rated_torque, self._heartbeat_ms, self._configure_pdos,
                                    self.errors, self.personality, self._serial, self.store)
        self.signals = ErrorSignals(self.errors, self.node, self.objects, self.machine)
        self._set_pdos({}, [])
        self.objects.store_configuration()
        self._restore(communication_only=False)
        self.node.on_stored(self._on_stored)
        self._refresh_sync_length()

    def _set_pdos(self, rpdos: dict[int, Rpdo], tpdos: list[TpdoSchedule]) -> None:
        """The PDOs as mapped now, and the replay's view of them."""
        self.rpdos = RpdoSet(rpdos, self.objects, self.machine, self.core, self.rated_torque)
        self.tpdos = TpdoSet(tpdos, self.node, self.machine, self.objects, self.core,
                             self.rated_torque)
        self.replay = ReplayView(self.node, self.tpdos, self.objects, self.rated_torque)

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
        router = self.router
        if (router is not None and router.handlers(0x600 + node_id)
                and node_id != UNCONFIGURED):
            log.warning("node id %d given by LSS is another drive's too: both answer", node_id)
        if self.node.has_network():
            self.node.nmt.stop_heartbeat()
            self._leave_pdos()
            self.node.remove_network()
        self._make_node(node_id)
        if node_id != UNCONFIGURED and router is not None and self._network is not None:
            self.node.associate_network(self._network)
            router.unsubscribe(NMT_ID, self._after_nmt)     # again after the node's NMT
            router.subscribe(NMT_ID, self._after_nmt)
            self._configure_pdos()
            self._boot()

    # --- network life cycle ---------------------------------------------------

    def subscriptions(self) -> list[Subscription]:
        return [Subscription(NMT_ID, self._after_nmt), Subscription(SYNC_ID, self._on_sync),
                Subscription(LSS_REQUEST_ID, self._on_lss)]

    def attach(self, router: FrameRouter) -> None:
        """Join the bus: PDO maps from the object dictionary, boot-up, heartbeat (a drive
        without a node id only listens for LSS)."""
        self._network = RoutedNetwork(router)
        if self.node_id != UNCONFIGURED:
            # its NMT slave before this drive's _after_nmt; not network.add_node (above)
            self.node.associate_network(self._network)
        super().attach(router)
        if self.node_id != UNCONFIGURED:
            self._configure_pdos()
            self._boot()

    def _on_lss(self, frame: Frame) -> None:
        with self.lock:
            self.lss.on_request(frame.data)

    def detach(self) -> None:
        if not self.attached:
            return
        self.node.nmt.stop_heartbeat()
        self._leave_pdos()
        super().detach()
        self.node.remove_network()
        self._network = None

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

    def _after_nmt(self, frame: Frame) -> None:
        """Runs after canopen's NMT slave has applied a command."""
        data = frame.data
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
        node, router = self.node, self.router
        self._leave_pdos()
        node.tpdo.read()
        node.rpdo.read()
        # read() subscribed canopen's PdoMap.on_message, which takes a Condition and
        # notifies its waiters on every frame (a drive has none): RPDOs come straight here,
        # and the drive hears none of its own TPDOs
        for pdo in node.tpdo.map.values():
            if pdo.enabled:
                node.network.unsubscribe(pdo.cob_id, pdo.on_message)
        for number, pdo in node.rpdo.map.items():
            if pdo.enabled:
                node.network.unsubscribe(pdo.cob_id, pdo.on_message)
                self._pdo_subscriptions.append(Subscription(
                    pdo.cob_id, functools.partial(self._on_rpdo, number),
                    extended_cob_id(pdo.cob_id)))
        self._set_pdos({number: Rpdo.of(pdo) for number, pdo in node.rpdo.map.items()},
                       tpdo_schedules(node))
        # RTRs answered on the TPDOs that allow them (as mapped now), and no others
        self._pdo_subscriptions += [Subscription(cob_id, self._on_remote,
                                                 extended_cob_id(cob_id), remote=True)
                                    for cob_id in self.tpdos.remote_ids]
        for subscription in self._pdo_subscriptions:
            subscription.join(router)

    def _leave_pdos(self) -> None:
        for subscription in self._pdo_subscriptions:
            subscription.leave(self.router)
        self._pdo_subscriptions = []

    # --- cyclic exchange --------------------------------------------------------

    def _on_rpdo(self, number: int, frame: Frame) -> None:
        if not self.node.nmt.operational:
            return                            # PDOs are off outside OPERATIONAL (CiA 301)
        data = frame.data
        rpdo = self.rpdos.rpdos[number]
        expected, size = rpdo.length, len(data)
        with self.lock:
            if size != expected:
                code = EMCY_PDO_LENGTH if size < expected else EMCY_PDO_LENGTH_EXCEEDED
                self.signals.frame_error(code, struct.pack("<HB", size, expected) + b"\0\0")
                if size < expected:
                    return
                data = data[:expected]
            elif self.errors.active:
                self.signals.end(PDO_ERRORS)            # an RPDO of its length again
            self._latched[number] = data
            self.core.new_setpoint(now=time.monotonic())
            if rpdo.immediate:
                self.rpdos.apply(number, data)

    def _on_sync(self, frame: Frame) -> None:
        data = frame.data
        with self.lock:
            self.sync_receive(data)
            self.tpdos.prepare(data[0] if len(data) == 1 else None)
            self.on_command(self)

    def sync_receive(self, data: bytes) -> None:
        """SYNC: take the latched setpoints (caller holds the lock). A SYNC carries a
        counter where 0x1019 (its overflow value) is over 0, none otherwise (CiA 301)."""
        operational = self.node.nmt.operational
        if len(data) != self._sync_length:
            self.signals.frame_error(EMCY_SYNC_LENGTH)
            return
        if self.errors.active:
            self.signals.end((EMCY_SYNC_LENGTH,))       # a SYNC of its length again
        if not operational:
            return
        latched, apply = self._latched, self.rpdos.apply
        for number in sorted(latched):
            apply(number, latched[number])
        latched.clear()

    def take_replies(self) -> list[Frame]:
        """The TPDOs packed at the last SYNC."""
        return self.tpdos.take()

    def _on_remote(self, frame: Frame) -> None:
        """An RTR on a TPDO's COB-ID (one that allows it)."""
        with self.lock:
            answer = self.tpdos.answer(frame.identifier)
            if answer is not None:
                self.send(answer)

    def tick(self, now: float) -> None:
        """The heartbeat, event-driven TPDOs (254, 255) and the heartbeat consumer (caller
        holds the lock)."""
        self.node.sdo.expire(now)
        self.machine.ramp_torque(now - self._last_tick)
        self._last_tick = now
        beat = self.node.nmt.heartbeat_due(now)
        if beat is not None:
            self.send(Frame(0x700 + self.node_id, beat))
        for producer in self.node.lost_heartbeats(now):
            log.warning("node %d: the heartbeat of node %d stopped", self.node_id, producer)
            self.core.lose_connection(Fault.HEARTBEAT_LOST)
        if self.node.nmt.operational:
            for frame in self.tpdos.due_events(now):
                self.send(frame)

    def after_update(self) -> None:
        """After the inner loops ran: state machine follow-ups and EMCY for new faults."""
        # (called at every plant step: the common case, nothing new, asks no more)
        events = self.take_events() if self.machine.after_update() else ()
        if self.router is None:             # detached: silent
            return
        for fault in events:
            self.signals.fault(fault)
        if self.errors.active:
            self.signals.settle(self.core.fault is not None, self.core.power is Power.ENABLED)

    def fault_words(self, fault: Fault) -> str:
        return f"{fault.text} (0x{EMCY_CODES[fault]:04X})"       # its EMCY code

    # --- what a replay compares (:mod:`.replay_view`) ---------------------------------

    def timed(self, frame: Frame) -> bool:
        return self.replay.timed(frame)

    def timed_ids(self) -> tuple[int, ...]:
        return self.replay.timed_ids()

    def timed_content(self, identifier: int) -> bytes | None:
        return self.replay.timed_content(identifier)

    def readings(self, frame: Frame) -> tuple[Reading, ...] | None:
        return self.replay.readings(frame)
