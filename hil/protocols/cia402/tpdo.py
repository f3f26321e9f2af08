"""When and what a simulated CiA 402 drive's TPDOs send: at SYNC (types 0-240, CiA 301), on an
event or the event timer (254, 255), and on a remote request (RTR) where the COB-ID allows it
(bit 30 clear): the values sampled at the last SYNC for type 252, the present ones otherwise
(253, and any other type, as CANopenNode answers). A SYNC that carries a counter (0x1019 > 0)
starts a TPDO of type 1-240 at the SYNC whose counter is its SYNC start value (0x1800+n
sub-index 6; 0: at once)."""

from __future__ import annotations

from hil.can.frame import Frame, frame_of_fields
from hil.drives.core import DriveCore
from hil.drives.definitions import DriveStatus
from hil.protocols.cia402.node import DriveNode
from hil.protocols.cia402.objects import DriveObjects
from hil.protocols.cia402.pdo import TpdoSchedule
from hil.protocols.cia402.state import Cia402StateMachine, live_values

#: TPDO COB-ID bit 30: no RTR allowed on this PDO (CiA 301)
NO_RTR = 0x40000000
SYNCHRONOUS_RTR = 252


class TpdoSet:
    """The TPDOs of one drive as mapped at its last PDO configuration (the module doc): their
    schedules, and what packing them reads (the node's dictionary, the state machine, the
    objects' units, the core's status). The drive makes a new one at each configuration."""

    def __init__(self, schedules: list[TpdoSchedule], node: DriveNode,
                 machine: Cia402StateMachine, objects: DriveObjects, core: DriveCore,
                 rated_torque: float):
        self.schedules = schedules
        self._node, self._machine, self._objects = node, machine, objects
        self._core, self._rated_torque = core, rated_torque
        #: the COB-IDs whose TPDOs answer an RTR
        self.remote_ids = tuple(s.cob_id for s in schedules if s.rtr_allowed)
        self._pending: list[Frame] = []

    def prepare(self, counter: int | None = None) -> None:
        """SYNC (with its counter, if it carries one): pack the synchronous TPDOs due at
        this SYNC with the current state (caller holds the lock): every n-th SYNC for types
        1-240, on a change for type 0."""
        self._pending = pending = []
        if not self._node.nmt.operational:
            return
        status = self._core.status()
        objects = self._objects
        machine, counts_per_rad, rated = self._machine, objects.counts_per_rad, self._rated_torque
        velocity_per_rad = objects.velocity_per_rad
        for schedule in self.schedules:
            kind = schedule.transmission_type
            if kind == SYNCHRONOUS_RTR:
                schedule.last_data = self._pack(schedule, status)   # what an RTR gets
            if kind > 240 or not (schedule.running or schedule.started(counter)):
                continue
            if kind > 0:
                schedule.syncs += 1
                if schedule.syncs < kind:
                    continue
                schedule.syncs = 0
            codec = schedule.codec      # _pack's common case here: a call less a TPDO
            data = (codec.pack(*live_values(schedule.indices, machine, status, counts_per_rad,
                                            rated, velocity_per_rad))
                    if codec is not None else self._pack(schedule, status))
            if kind == 0:
                if data == schedule.last_data:
                    continue
                schedule.last_data = data
            # built from C (Frame's own __new__ is a Python call a TPDO)
            pending.append(frame_of_fields((schedule.cob_id, data, schedule.extended, False,
                                            False, False, False, 0.0)))

    def take(self) -> list[Frame]:
        """The TPDOs :meth:`prepare` packed, each taken once."""
        pending, self._pending = self._pending, []
        return pending

    def due_events(self, now: float) -> list[Frame]:
        """Event-driven TPDOs (254, 255) whose data changed (past the inhibit time) or whose
        event timer ran out, as sent at ``now`` (caller holds the lock, node OPERATIONAL)."""
        status: DriveStatus | None = None
        due = []
        for schedule in self.schedules:
            if not schedule.event_driven or now - schedule.last_sent < schedule.inhibit:
                continue
            status = status or self._core.status()
            data = self._pack(schedule, status)
            timer = schedule.event_timer
            if data != schedule.last_data or (timer > 0 and now - schedule.last_sent >= timer):
                schedule.last_data, schedule.last_sent = data, now
                due.append(Frame(schedule.cob_id, data, schedule.extended))
        return due

    def answer(self, cob_id: int) -> Frame | None:
        """The answer to an RTR on ``cob_id``: its TPDO, where it allows RTR, in OPERATIONAL
        (caller holds the lock)."""
        if not self._node.nmt.operational:
            return None
        for schedule in self.schedules:
            if schedule.cob_id == cob_id and schedule.rtr_allowed:
                data = (schedule.last_data if schedule.transmission_type == SYNCHRONOUS_RTR
                        else None) or self._pack(schedule, self._core.status())
                return Frame(cob_id, data, schedule.extended)
        return None

    def _pack(self, schedule: TpdoSchedule, status: DriveStatus) -> bytes:
        if schedule.codec is not None:
            return schedule.codec.pack(*live_values(
                schedule.indices, self._machine, status, self._objects.counts_per_rad,
                self._rated_torque, self._objects.velocity_per_rad))
        pdo = schedule.pdo
        for variable in pdo.map:     # through the object dictionary, live or stored
            variable.set_data(self._node.get_data(variable.index, variable.subindex))
        return bytes(pdo.data)
