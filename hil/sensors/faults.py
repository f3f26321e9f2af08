"""The faults ``hil sim --fault`` injects into a sensor (:class:`SensorFaults`), kept by
plant time so that a lock-step run fails at the same sample every time."""

from __future__ import annotations

from hil.can.faults import SensorFaultKind


class SensorFaults:
    """One sensor's faults to come, and those it is in: silent (it sends or answers nothing
    more), freezing (it repeats what it sent when the fault came), a spike (one sample at
    full scale)."""

    def __init__(self):
        self._coming: list[tuple[float, SensorFaultKind]] = []     # by plant time
        self.silent = False
        self.freezing = False

    def inject(self, kind: SensorFaultKind, at: float) -> None:
        """Fail as ``kind`` says at plant time ``at`` (s)."""
        self._coming.append((at, kind))
        self._coming.sort(key=lambda fault: fault[0])

    def reach(self, now: float) -> bool:
        """Enter the faults due by plant time ``now`` (s); whether this sample spikes."""
        spike = False
        # plant time is a sum of floats: a fault at a sample's time is that sample's
        while self._coming and self._coming[0][0] <= now + 1e-9:
            kind = self._coming.pop(0)[1]
            self.silent |= kind is SensorFaultKind.SILENCE
            self.freezing |= kind is SensorFaultKind.FREEZE
            spike |= kind is SensorFaultKind.SPIKE
        return spike
