"""What the controller reports about the drives, as ROS 2 diagnostics.

A fault the control loop sees (a silent drive, a drive in FAULT, a quick stop of its own)
aborts the active goal with the reason; with no goal active it would reach only the
controller's log. Each one is also published on ``hil/<robot>/diagnostics`` as a
diagnostic_msgs/DiagnosticArray (level ERROR), and a fault reset that brings every drive
back as level OK, so that ``hil up`` prints them as they happen and ``hil viz`` puts them
on the recording's timelines.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from hil.hardware import AxisFault
from hil.messaging import cdr

#: DiagnosticStatus.level, by value
LEVELS = ("OK", "WARN", "ERROR", "STALE")
#: the KeyValue that carries the controller's clock (lock-step runs faster than the wall)
CONTROL_TIME = "control_time"


@dataclass(frozen=True)
class DiagnosticStatus:
    """One report: ``level`` one of :data:`LEVELS`; ``control_time`` the controller's clock
    (None from a publisher that does not say)."""

    level: str
    message: str
    wall_time: float                 # s since the epoch
    control_time: float | None
    name: str = "hil control"
    hardware_id: str = ""            # the robot
    #: what the report is about, as diagnostic_msgs KeyValues (a fault: kind, bus, node_id,
    #: joints, code)
    values: tuple[tuple[str, str], ...] = ()

    def encode(self) -> bytes:
        pairs = list(self.values) if self.control_time is None else [
            (CONTROL_TIME, repr(self.control_time)), *self.values]
        values = [cdr.msg("diagnostic_msgs/msg/KeyValue", key=k, value=v) for k, v in pairs]
        status = cdr.msg(cdr.DIAGNOSTIC_STATUS, level=LEVELS.index(self.level), name=self.name,
                         message=self.message, hardware_id=self.hardware_id, values=values)
        return cdr.encode(cdr.msg(cdr.DIAGNOSTIC_ARRAY, header=cdr.header(self.wall_time),
                                  status=[status]))

    @classmethod
    def decode(cls, data: bytes) -> list[DiagnosticStatus]:
        """Every status of a DiagnosticArray; raise ValueError naming what is wrong."""
        message = cdr.decode(data, cdr.DIAGNOSTIC_ARRAY)
        wall_time = cdr.seconds_of(message.header.stamp)
        found = []
        for status in message.status:
            if not 0 <= status.level < len(LEVELS):
                raise ValueError(f"malformed {cdr.DIAGNOSTIC_ARRAY}: level {status.level} of "
                                 f"'{status.name}' (0-{len(LEVELS) - 1} exist)")
            found.append(cls(LEVELS[status.level], status.message, wall_time,
                             _control_time(status), status.name, status.hardware_id,
                             tuple((p.key, p.value) for p in status.values
                                   if p.key != CONTROL_TIME)))
        return found


def fault_values(fault: AxisFault) -> tuple[tuple[str, str], ...]:
    """A fault's data as KeyValues: kind, bus, node_id, joints (comma-separated), and code
    (hex) where the drive sent one."""
    code = () if fault.code is None else (("code", f"0x{fault.code:04X}"),)
    return (("kind", fault.kind.value), ("bus", fault.bus), ("node_id", str(fault.node_id)),
            ("joints", ",".join(fault.joints)), *code)


def _control_time(status) -> float | None:
    for pair in status.values:
        if pair.key == CONTROL_TIME:
            try:
                value = float(pair.value)
            except ValueError:
                value = math.nan
            if not math.isfinite(value):
                raise ValueError(f"malformed {cdr.DIAGNOSTIC_ARRAY}: {CONTROL_TIME} "
                                 f"'{pair.value}' of '{status.name}' is not a finite number")
            return value
    return None
