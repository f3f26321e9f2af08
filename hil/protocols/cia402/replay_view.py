"""What a replay compares of a CiA 402 drive's frames (:class:`DriveProfile`'s replay
contract): which frames are timed, and a TPDO's live objects as readings."""

from __future__ import annotations

import canopen

from hil.drives.profile import Reading

#: the heartbeat's NMT state codes (CiA 301)
NMT_CODES = {name: code for code, name in canopen.nmt.NMT_STATES.items()}
#: what each live object measures (hil.drives.profile.QUANTITIES; None: exact), by index
MEASURES = {0x6064: "position", 0x60F4: "position", 0x606C: "velocity", 0x6077: "torque"}
#: statusword bits the drive sets from what it measures (target reached, internal limit
#: active, following error): they flip with the timing of a run
MEASURED_STATUS = 0x2C00


class ReplayView:
    """The replay contract of :class:`hil.protocols.cia402.drive.Cia402Drive` (a mixin over
    its node, TPDO schedules and scales)."""

    def timed(self, can_id: int, data: bytes) -> bool:
        """The heartbeat (not the boot-up, which answers a reset) and event-driven TPDOs."""
        if can_id == 0x700 + self.node_id:
            return bytes(data[:1]) != b"\x00"
        return any(s.event_driven and s.pdo.cob_id == can_id for s in self._tpdos)

    def timed_ids(self) -> tuple[int, ...]:
        return (0x700 + self.node_id,)

    def timed_content(self, can_id: int) -> bytes | None:
        if can_id == 0x700 + self.node_id:
            return bytes([NMT_CODES[self.node.nmt.state]])
        return None

    def readings(self, can_id: int, data: bytes) -> tuple[Reading, ...] | None:
        """A TPDO's live objects (as mapped now): positions and velocities in counts,
        torque in per mille of the rated torque, the rest exact."""
        for schedule in self._tpdos:
            if schedule.pdo.cob_id != can_id or schedule.codec is None:
                continue
            if len(data) != schedule.codec.size:
                return None
            scales = {"position": 1 / self._counts_per_rad,
                      "velocity": 1 / self.objects.velocity_per_rad,
                      "torque": self.rated_torque / 1000}
            found = []
            for index, value in zip(schedule.indices, schedule.codec.unpack(data)):
                if index == 0x6041:      # the state exact; what the position loop sets, derived
                    found += [Reading("0x6041", value & ~MEASURED_STATUS, None),
                              Reading("0x6041 bits 10, 11, 13", value & MEASURED_STATUS,
                                      "derived")]
                else:
                    found.append(Reading(f"0x{index:04X}", value, MEASURES.get(index),
                                         scales.get(MEASURES.get(index), 1.0)))
            return tuple(found)
        return None
