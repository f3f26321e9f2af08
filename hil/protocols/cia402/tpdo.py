"""When and what a simulated CiA 402 drive's TPDOs send (a mixin of
:class:`hil.protocols.cia402.drive.Cia402Drive`, over its node, schedules and state): at
SYNC (types 0-240, CiA 301), on an event or the event timer (254, 255), and on a remote
request (RTR) where the COB-ID allows it (bit 30 clear): the values sampled at the last SYNC
for type 252, the present ones otherwise (253, and any other type, as CANopenNode answers).
A SYNC that carries a counter (0x1019 > 0) starts a TPDO of type 1-240 at the SYNC whose
counter is its SYNC start value (0x1800+n sub-index 6; 0: at once)."""

from __future__ import annotations

from hil.protocols.cia402.pdo import TpdoSchedule
from hil.protocols.cia402.state import live_values

#: TPDO COB-ID bit 30: no RTR allowed on this PDO (CiA 301)
NO_RTR = 0x40000000
SYNCHRONOUS_RTR = 252


class TpdoProducer:
    """The TPDO side of a CiA 402 drive (the module doc)."""

    def prepare_tpdos(self, counter: int | None = None) -> None:
        """SYNC (with its counter, if it carries one): pack the synchronous TPDOs due at
        this SYNC with the current state (caller holds the lock): every n-th SYNC for types
        1-240, on a change for type 0."""
        self._pending = []
        if not self.node.nmt.operational:
            return
        status = self.core.status()
        pending = self._pending
        objects = self.objects
        machine, counts_per_rad, rated = self.machine, objects.counts_per_rad, self.rated_torque
        velocity_per_rad = objects.velocity_per_rad
        for schedule in self._tpdos:
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
            pending.append((schedule.pdo.cob_id, data))

    def _pack(self, schedule: TpdoSchedule, status) -> bytes:
        if schedule.codec is not None:
            return schedule.codec.pack(*live_values(
                schedule.indices, self.machine, status, self.objects.counts_per_rad,
                self.rated_torque, self.objects.velocity_per_rad))
        pdo = schedule.pdo
        for variable in pdo.map:     # through the object dictionary, live or stored
            variable.set_data(self.node.get_data(variable.index, variable.subindex))
        return bytes(pdo.data)

    def take_replies(self) -> list[tuple[int, bytes]]:
        """The TPDOs :meth:`prepare_tpdos` packed."""
        pending, self._pending = self._pending, []
        return pending

    def send_event_tpdos(self, now: float) -> None:
        """Event-driven TPDOs (254, 255) whose data changed (past the inhibit time) or whose
        event timer ran out (caller holds the lock, node OPERATIONAL)."""
        status = None
        for schedule in self._tpdos:
            if not schedule.event_driven or now - schedule.last_sent < schedule.inhibit:
                continue
            status = status or self.core.status()
            data = self._pack(schedule, status)
            timer = schedule.event_timer
            if data != schedule.last_data or (timer > 0 and now - schedule.last_sent >= timer):
                schedule.last_data, schedule.last_sent = data, now
                self.send(schedule.pdo.cob_id, data)

    def remote_requested(self, can_id: int) -> None:
        """An RTR on a TPDO's COB-ID: the TPDO, where it allows RTR, in OPERATIONAL."""
        with self.lock:
            if not self.node.nmt.operational:
                return
            for schedule in self._tpdos:
                if schedule.pdo.cob_id == can_id and schedule.rtr_allowed:
                    data = (schedule.last_data if schedule.transmission_type == SYNCHRONOUS_RTR
                            else None) or self._pack(schedule, self.core.status())
                    self.send(can_id, data)
                    return

    def serve_remote_requests(self, network) -> None:
        """Answer RTRs on the TPDOs that allow them (as mapped now), and no others."""
        handlers = network.frame_listener.remote_handlers
        for can_id in self._remote_ids:
            handlers.pop(can_id, None)
        self._remote_ids = [s.pdo.cob_id for s in self._tpdos if s.rtr_allowed]
        for can_id in self._remote_ids:
            handlers[can_id] = self.remote_requested
