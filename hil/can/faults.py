"""Fault injection: a python-can bus that loses, delays and corrupts frames, and the
fault specifications ``hil sim --fault`` / ``hil up --fault`` take.

Specifications (repeatable options):

=========================  ===========================================================
``drop:BUS:FRACTION``      lose that fraction of the frames on BUS, both directions
``delay:BUS:FRACTION:MS``  hold that fraction of the drives' frames on BUS for MS ms
``corrupt:BUS:FRACTION``   flip one random bit in that fraction of the frames' data
``silence:BUS/NODE@S``     the drive leaves the bus (no frames in or out)
``fault:BUS/NODE@S``       the drive faults as on a following error (EMCY, FAULT...)
``restart:BUS/NODE@S``     the drive restarts as after a power cycle (boots unconfigured)
``kill:PROCESS@S``         ``hil up`` kills its child PROCESS (sim, control, viz)
``silence:SENSOR@S``       the sensor sends nothing more (unplugged)
``freeze:SENSOR@S``        the sensor sends its last sample again and again (stuck)
``spike:SENSOR@S``         the sensor's sample at S reads full scale on every axis
=========================  ===========================================================

S is seconds of the plant's time after every drive was first enabled (drive faults, in
``hil sim``: in lock-step, the same moment of the run however fast it goes) or seconds
after every process is up (kills, in ``hil up``), or seconds of the plant's time from
its start (sensor faults: a sensor serves from the start, with or without a master). The
random choices come from one seeded generator, so a run can be repeated.
"""

from __future__ import annotations

import enum
import heapq
import random
import re
import threading
import time
from dataclasses import dataclass

import can

from hil.can.capabilities import BusCapabilities, capabilities
from hil.errors import HilError

PROCESSES = ("sim", "control", "viz")


class FrameFaultKind(enum.Enum):
    """What happens to a fraction of a bus' frames."""

    DROP = "drop"
    DELAY = "delay"
    CORRUPT = "corrupt"


class DriveFaultKind(enum.Enum):
    """What happens to one drive at a moment of the run."""

    SILENCE = "silence"     # it leaves the bus
    FAULT = "fault"         # it faults as on a following error
    RESTART = "restart"     # it restarts as after a power cycle


class SensorFaultKind(enum.Enum):
    """What happens to one sensor at a moment of the run (hil's choice of the three ways
    a sensor fails that a controller must notice: issue 70)."""

    SILENCE = "silence"     # it sends nothing more
    FREEZE = "freeze"       # it repeats its last sample
    SPIKE = "spike"         # one sample at full scale


@dataclass(frozen=True)
class FrameFault:
    kind: FrameFaultKind    # or its word ("drop"), made the kind
    bus: str
    fraction: float
    delay: float = 0.0      # s (delay only)

    def __post_init__(self):
        object.__setattr__(self, "kind", FrameFaultKind(self.kind))


@dataclass(frozen=True)
class DriveFault:
    kind: DriveFaultKind    # or its word ("silence"), made the kind
    bus: str
    node_id: int
    at: float               # s after start

    def __post_init__(self):
        object.__setattr__(self, "kind", DriveFaultKind(self.kind))


@dataclass(frozen=True)
class SensorFault:
    kind: SensorFaultKind
    sensor: str
    at: float               # s of plant time


FRAME_FAULT_WORDS = tuple(kind.value for kind in FrameFaultKind)
DRIVE_FAULT_WORDS = tuple(kind.value for kind in DriveFaultKind)
SENSOR_FAULT_WORDS = tuple(kind.value for kind in SensorFaultKind)


@dataclass(frozen=True)
class ProcessFault:
    process: str
    at: float


def parse_fault(text: str) -> FrameFault | DriveFault | ProcessFault | SensorFault:
    """One ``--fault`` specification; HilError with the accepted forms otherwise."""
    hint = ("forms: drop:BUS:FRACTION, delay:BUS:FRACTION:MS, corrupt:BUS:FRACTION, "
            "silence:BUS/NODE@S, fault:BUS/NODE@S, restart:BUS/NODE@S, "
            "kill:sim|control|viz@S, silence|freeze|spike:SENSOR@S")
    word, _, rest = text.partition(":")
    try:
        if word in FRAME_FAULT_WORDS:
            kind = FrameFaultKind(word)
            parts = rest.split(":")
            if len(parts) != (3 if kind is FrameFaultKind.DELAY else 2):
                raise ValueError("wrong number of fields")
            fraction = float(parts[1])
            if not 0.0 < fraction <= 1.0:
                raise ValueError(f"fraction {fraction} is not in (0, 1]")
            delay = float(parts[2]) / 1000 if kind is FrameFaultKind.DELAY else 0.0
            if delay < 0:
                raise ValueError("a delay cannot be negative")
            return FrameFault(kind, parts[0], fraction, delay)
        match = re.fullmatch(r"(\w[\w/-]*)/(\d+)@([\d.]+)s?", rest)
        if word in DRIVE_FAULT_WORDS and match:
            return DriveFault(DriveFaultKind(word), match.group(1), int(match.group(2)),
                              float(match.group(3)))
        match = re.fullmatch(r"(\w[\w-]*)@([\d.]+)s?", rest)
        if word == "kill" and match and match.group(1) in PROCESSES:
            return ProcessFault(match.group(1), float(match.group(2)))
        if word in SENSOR_FAULT_WORDS and match:
            return SensorFault(SensorFaultKind(word), match.group(1), float(match.group(2)))
        raise ValueError("not a known fault")
    except ValueError as exc:
        raise HilError.single(f"--fault '{text}': {exc}", hint=hint) from None


class FaultyBus(can.BusABC, BusCapabilities):
    """Wraps a python-can bus: drops, delays and corrupts frames as its faults say.

    Drops and corruption apply to frames sent and received through this bus;
    delays to frames sent (a delayed frame keeps its order among delayed frames).
    """

    def __init__(self, inner: can.BusABC, faults: list[FrameFault], seed: int = 0):
        self.inner = inner
        self.faults = list(faults)
        self.channel_info = f"{inner.channel_info} with faults " + ", ".join(
            f"{f.kind.value} {f.fraction:g}" for f in self.faults)
        #: frames each kind of fault took, by its word
        self.injected = {kind.value: 0 for kind in FrameFaultKind}
        self._random = random.Random(seed)
        self._lock = threading.Lock()
        self._delayed: list[tuple[float, int, can.Message]] = []
        self._wake = threading.Condition()
        self._count = 0
        self._closing = False
        self._worker = threading.Thread(target=self._send_delayed, daemon=True,
                                        name=f"delays on {inner.channel_info}")
        self._worker.start()
        super().__init__(channel=inner.channel_info)

    def add(self, fault: FrameFault) -> None:
        """Start injecting another fault (e.g. once a stack is up)."""
        with self._lock:
            self.faults.append(fault)

    def _chance(self, kind: FrameFaultKind) -> FrameFault | None:
        with self._lock:
            for fault in self.faults:
                if fault.kind == kind and self._random.random() < fault.fraction:
                    self.injected[kind.value] += 1
                    return fault
        return None

    def _corrupted(self, msg: can.Message) -> can.Message:
        if msg.dlc == 0 or msg.is_remote_frame or self._chance(FrameFaultKind.CORRUPT) is None:
            return msg
        data = bytearray(msg.data)
        with self._lock:
            bit = self._random.randrange(8 * len(data))
        data[bit // 8] ^= 1 << (bit % 8)
        return can.Message(timestamp=msg.timestamp, arbitration_id=msg.arbitration_id,
                           is_extended_id=msg.is_extended_id, data=bytes(data),
                           channel=msg.channel, is_rx=msg.is_rx)

    def send(self, msg: can.Message, timeout: float | None = None) -> None:
        if not self.faults:                      # the usual case: a plain pass-through
            self.inner.send(msg, timeout)
            return
        if self._chance(FrameFaultKind.DROP):
            return
        msg = self._corrupted(msg)
        delay = self._chance(FrameFaultKind.DELAY)
        if delay is None:
            self.inner.send(msg, timeout)
            return
        with self._wake:
            self._count += 1
            heapq.heappush(self._delayed, (time.monotonic() + delay.delay, self._count, msg))
            self._wake.notify()

    def _send_delayed(self) -> None:
        with self._wake:
            while not self._closing:
                if not self._delayed:
                    self._wake.wait()
                    continue
                due, _, msg = self._delayed[0]
                wait = due - time.monotonic()
                if wait > 0:
                    self._wake.wait(wait)
                    continue
                heapq.heappop(self._delayed)
                try:
                    self.inner.send(msg)
                except can.CanError:
                    pass

    # the wrapped bus' capabilities, through this one

    @property
    def counters(self):
        return capabilities(self.inner).counters

    def deliver_to(self, listeners, accept=None):
        """Direct delivery (see hil.can.delivery) where the wrapped bus offers it, after this
        bus' receive-side faults (then ``accept``)."""
        def received(msg: can.Message) -> can.Message | None:
            msg = self._received(msg)
            return msg if msg is None or accept is None else accept(msg)
        return capabilities(self.inner).deliver_to(listeners, received)

    def batch(self):
        return capabilities(self.inner).batch()

    def deliver_under(self, guard) -> None:
        capabilities(self.inner).deliver_under(guard)

    def watch_stalls(self, on_stall) -> None:
        capabilities(self.inner).watch_stalls(on_stall)

    def unreached(self) -> str | None:
        return capabilities(self.inner).unreached()

    def _received(self, msg: can.Message) -> can.Message | None:
        """A received frame after this bus' receive faults: dropped (None) or corrupted."""
        if not self.faults:
            return msg
        return None if self._chance(FrameFaultKind.DROP) else self._corrupted(msg)

    def _recv_internal(self, timeout: float | None) -> tuple[can.Message | None, bool]:
        if not self.faults:
            return self.inner.recv(timeout), False
        deadline = None if timeout is None else time.monotonic() + timeout
        while True:
            msg = self.inner.recv(None if deadline is None
                                  else max(0.0, deadline - time.monotonic()))
            if msg is None:
                return None, False
            msg = self._received(msg)
            if msg is not None:
                return msg, False

    def shutdown(self) -> None:
        if self._is_shutdown:
            return
        with self._wake:
            self._closing = True
            self._wake.notify()
        self._worker.join(1)
        super().shutdown()
        self.inner.shutdown()


def with_frame_faults(buses: dict[str, can.BusABC], faults: list[FrameFault],
                      seed: int = 0) -> dict[str, can.BusABC]:
    """The buses, those named in ``faults`` wrapped in a FaultyBus."""
    unknown = {f.bus for f in faults} - set(buses)
    if unknown:
        raise HilError.single(f"--fault names unknown bus(es) {', '.join(sorted(unknown))}",
                              hint=f"buses: {', '.join(buses)}")
    return {name: FaultyBus(bus, [f for f in faults if f.bus == name], seed)
            if any(f.bus == name for f in faults) else bus for name, bus in buses.items()}
