"""hil's Zenoh API: the publications and subscriptions of the processes (joint states,
control samples, the sim's clock, diagnostics, liveliness), and, from
:mod:`hil.messaging.action`, the trajectory action. Keys: :mod:`hil.messaging.keys`.
"""

from __future__ import annotations

import threading
from collections.abc import Callable
from typing import Any

import zenoh

from hil.controllers import GoalStatus
from hil.messaging import cdr
from hil.messaging.action import (
    ControllerGone, TrajectoryActionClient, TrajectoryActionServer, WaitStopped,
)
from hil.messaging.diagnostics import DiagnosticStatus
from hil.messaging.keys import IMU, WRENCH, key, sensor_key
from hil.messaging.samples import ControlSamples
from hil.messaging.scene import SceneState
from hil.messaging.sensors import ImuMessage, WrenchMessage
from hil.realtime.side_work import SideWorkQueue
from hil.realtime.stalls import Stall


class JointStatePublisher:
    """Publishes sensor_msgs/JointState on ``hil/<robot>/joint_states``."""

    def __init__(self, session: zenoh.Session, robot: str):
        self._publisher = session.declare_publisher(key(robot, "joint_states"))

    def put(self, payload: bytes) -> None:
        """Put joint states already encoded (:func:`hil.messaging.cdr.joint_state_msg`)."""
        self._publisher.put(payload)

    def close(self) -> None:
        self._publisher.undeclare()


class SensorPublisher:
    """Publishes a sensor's samples on ``hil/<robot>/sensors/<name>/<kind>``."""

    def __init__(self, session: zenoh.Session, robot: str, name: str, kind: str):
        self._publisher = session.declare_publisher(key(robot, sensor_key(name, kind)))

    def put(self, payload: bytes) -> None:
        """Put a sample already encoded (:class:`hil.messaging.cdr.ImuCdr`, ``WrenchCdr``)."""
        self._publisher.put(payload)

    def close(self) -> None:
        self._publisher.undeclare()


class ControlSamplesPublisher:
    """Publishes hil_msgs/ControlSamples batches on ``hil/<robot>/control/samples``.

    :meth:`publish` only queues the batch: a thread of its own encodes and puts it with
    congestion control BLOCK (a recording must not lose cycles to a momentarily slow
    subscriber), so a slow visualiser never holds the control loop (it did: BLOCK in the
    loop's thread). The thread runs at the process' side-work priority
    (:func:`hil.realtime.enter_side_work`): below its frame handling, above normal
    processes (under the normal scheduler it was preempted holding the GIL, and the loop
    waited for it for cycles: docs/performance.md,
    "2026-12-06, later: figures from code comments"). A visualiser that falls behind by more
    than BACKLOG batches loses the newest ones, counted in :attr:`dropped` (and its
    recording shows the gap)."""

    BACKLOG = 600            # 60 s of batches at 10 Hz

    def __init__(self, session: zenoh.Session, robot: str):
        self._publisher = session.declare_publisher(
            key(robot, "control/samples"), congestion_control=zenoh.CongestionControl.BLOCK)
        ControlSamples.empty().encode()    # rosbags builds its codec on first use: not in a cycle
        self._work = SideWorkQueue(lambda samples: self._publisher.put(samples.encode()),
                                   self.BACKLOG, "control samples")

    @property
    def dropped(self) -> int:
        return self._work.dropped

    def publish(self, samples: ControlSamples) -> None:
        self._work.put(samples)

    def close(self, timeout: float = 10.0) -> None:
        """Publish what is queued (for up to ``timeout`` s), then stop."""
        self._work.close(timeout)
        self._publisher.undeclare()


class SimClockPublisher:
    """Publishes hil_msgs/SimClock (plant time against wall time) on ``hil/<robot>/sim/clock``."""

    def __init__(self, session: zenoh.Session, robot: str):
        self._publisher = session.declare_publisher(key(robot, "sim/clock"))

    def publish(self, wall_time: float, sim_time: float) -> None:
        self._publisher.put(cdr.encode(cdr.msg(cdr.SIM_CLOCK, wall_time=wall_time, sim_time=sim_time)))

    def close(self) -> None:
        self._publisher.undeclare()


class ScenePublisher:
    """Publishes the plant's scene (hil_msgs/SceneState) on ``hil/<robot>/sim/scene``."""

    def __init__(self, session: zenoh.Session, robot: str):
        self._publisher = session.declare_publisher(key(robot, "sim/scene"))

    def publish(self, state: SceneState) -> None:
        self._publisher.put(state.encode())

    def close(self) -> None:
        self._publisher.undeclare()


class StallPublisher:
    """Publishes a real-time process' stalls (hil_msgs/Stall) on ``hil/<robot>/stalls``, for
    the controller to hold against the drives it finds silent. :meth:`publish` never blocks
    (a stall is found in the loop that stalled, or in Zenoh's delivering thread): the put is
    side work."""

    def __init__(self, session: zenoh.Session, robot: str):
        # BLOCK: the report that explains a fault must not be dropped under load
        self._publisher = session.declare_publisher(
            key(robot, "stalls"), congestion_control=zenoh.CongestionControl.BLOCK)
        self._work = SideWorkQueue(self._put, 64, "stalls")

    def publish(self, stall: Stall) -> None:
        self._work.put(stall)

    def _put(self, stall: Stall) -> None:
        self._publisher.put(cdr.encode(cdr.msg(
            cdr.STALL, process=stall.process, at=stall.at, length=stall.length,
            steal=stall.steal, where=stall.where)))

    def close(self) -> None:
        self._work.close(1.0)
        self._publisher.undeclare()


def decode_stall(data: bytes) -> Stall:
    """A hil_msgs/Stall payload as a :class:`Stall`; ValueError if it is not one."""
    got = cdr.decode(data, cdr.STALL)
    return Stall(got.process, got.at, got.length, got.steal, where=got.where)


class MalformedPayloads:
    """A subscriber's malformed payloads: counted, and the first and every REPORT_EVERY-th
    told through ``on_error`` (key, count, reason), so that a flood of them is a count and
    a few lines, not a line each."""

    REPORT_EVERY = 1000

    def __init__(self, on_error: Callable[[str], None]):
        self.count = 0
        self._on_error = on_error
        self._lock = threading.Lock()      # Zenoh delivers on several threads

    def __call__(self, key_expr, problem: ValueError) -> None:
        with self._lock:
            self.count += 1
            count = self.count
        if count % self.REPORT_EVERY == 1:
            self._on_error(f"{key_expr}: dropped a malformed payload ({count} so far): "
                           f"{problem}")


class StallSubscriber:
    """Receives the stalls of a robot's real-time processes (this process' own among them);
    a malformed payload is reported through ``on_error`` (key and reason), never passed on."""

    def __init__(self, session: zenoh.Session, robot: str, on_stall: Callable[[Stall], None],
                 on_error: Callable[[str], None]):
        malformed = MalformedPayloads(on_error)

        def on_sample(sample: zenoh.Sample) -> None:
            try:
                stall = decode_stall(sample.payload.to_bytes())
            except ValueError as exc:
                malformed(sample.key_expr, exc)
                return
            on_stall(stall)

        self._subscriber = session.declare_subscriber(key(robot, "stalls"), on_sample)

    def close(self) -> None:
        self._subscriber.undeclare()


class DiagnosticsPublisher:
    """Publishes diagnostic_msgs/DiagnosticArray on ``hil/<robot>/diagnostics``."""

    def __init__(self, session: zenoh.Session, robot: str):
        # BLOCK: a fault report must not be dropped under load
        self._publisher = session.declare_publisher(
            key(robot, "diagnostics"), congestion_control=zenoh.CongestionControl.BLOCK)

    def put(self, payload: bytes) -> None:
        """Put a DiagnosticArray already encoded (:meth:`DiagnosticStatus.encode`)."""
        self._publisher.put(payload)

    def close(self) -> None:
        self._publisher.undeclare()


class RunSubscriber:
    """Receives a robot's recorded cycles, sim clock and (given ``on_diagnostic``,
    ``on_stall``, ``on_scene``, ``on_imu`` and ``on_wrench``) the controller's diagnostics, the
    real-time processes' stalls, the plant's scene and the sensors' samples;
    malformed payloads are counted (``malformed.count``) and reported through ``on_error``
    (:class:`MalformedPayloads`), never passed on.""" 

    def __init__(self, session: zenoh.Session, robot: str,
                 on_samples: Callable[[ControlSamples], None],
                 on_clock: Callable[[float, float], None],
                 on_error: Callable[[str], None],
                 on_diagnostic: Callable[[DiagnosticStatus], None] | None = None,
                 on_stall: Callable[[Stall], None] | None = None,
                 on_scene: Callable[[SceneState], None] | None = None,
                 on_imu: Callable[[ImuMessage], None] | None = None,
                 on_wrench: Callable[[WrenchMessage], None] | None = None):
        self.malformed = MalformedPayloads(on_error)
        self._subscribers: list[zenoh.Subscriber] = []
        self._subscribe(session, key(robot, "control/samples"), ControlSamples.decode,
                        on_samples)
        self._subscribe(session, key(robot, "sim/clock"),
                        lambda data: cdr.decode(data, cdr.SIM_CLOCK),
                        lambda clock: on_clock(clock.wall_time, clock.sim_time))
        if on_diagnostic is not None:
            def each(diagnostics: list[DiagnosticStatus]) -> None:
                for diagnostic in diagnostics:
                    on_diagnostic(diagnostic)

            self._subscribe(session, key(robot, "diagnostics"), DiagnosticStatus.decode, each)
        if on_stall is not None:
            self._subscribe(session, key(robot, "stalls"), decode_stall, on_stall)
        if on_scene is not None:
            self._subscribe(session, key(robot, "sim/scene"), SceneState.decode, on_scene)
        if on_imu is not None:
            self._subscribe(session, key(robot, sensor_key("*", IMU)), ImuMessage.decode,
                            on_imu, with_key=True)
        if on_wrench is not None:
            self._subscribe(session, key(robot, sensor_key("*", WRENCH)), WrenchMessage.decode,
                            on_wrench, with_key=True)

    def _subscribe(self, session: zenoh.Session, key_expr: str, decode: Callable[..., Any],
                   deliver: Callable[[Any], Any], with_key: bool = False) -> None:
        """``decode`` takes the payload, or with ``with_key`` the sample's key and payload."""
        def on_sample(sample: zenoh.Sample) -> None:
            try:
                payload = sample.payload.to_bytes()
                decoded = (decode(str(sample.key_expr), payload) if with_key
                           else decode(payload))
            except ValueError as exc:
                self.malformed(sample.key_expr, exc)
                return
            deliver(decoded)

        self._subscribers.append(session.declare_subscriber(key_expr, on_sample))

    def close(self) -> None:
        for subscriber in self._subscribers:
            subscriber.undeclare()


class ProcessWatch:
    """Which of a robot's processes (``sim``, ``control``, ``viz``) are alive, and in what
    phase (``control/held``: waiting to bring its drives up), from their liveliness tokens."""

    def __init__(self, session: zenoh.Session, robot: str):
        self._prefix = key(robot, "")
        self._alive: set[str] = set()
        self._changed = threading.Condition()
        self._subscriber = session.liveliness().declare_subscriber(
            key(robot, "**"), self._on_token, history=True)

    def _on_token(self, sample: zenoh.Sample) -> None:
        name = str(sample.key_expr).removeprefix(self._prefix)
        with self._changed:
            if sample.kind == zenoh.SampleKind.PUT:
                self._alive.add(name)
            else:
                self._alive.discard(name)
            self._changed.notify_all()

    def wait_alive(self, name: str, timeout: float) -> bool:
        with self._changed:
            return self._changed.wait_for(lambda: name in self._alive, timeout)

    def close(self) -> None:
        self._subscriber.undeclare()


__all__ = ["ControlSamplesPublisher", "ControllerGone", "DiagnosticsPublisher", "GoalStatus",
           "JointStatePublisher", "ProcessWatch", "RunSubscriber", "SimClockPublisher",
           "StallPublisher", "StallSubscriber", "decode_stall",
           "TrajectoryActionClient", "TrajectoryActionServer", "WaitStopped", "key"]
