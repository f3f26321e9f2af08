"""Logging a run into rerun: every axis on sim-time and wall-time timelines, the 3D robot.

A recording's bytes go to the rows of its entities (each row its row id and three times,
40 bytes before any value) and to its chunks (each about 0.5 KB of Arrow framing), not to
its values. So every signal of a control cycle shares one row of one entity, ``cycle``,
as 4-byte floats (a 17-bit encoder's count is 5e-5 rad: a float's 24-bit mantissa holds a
joint's position to 4e-7 rad), one chunk per batch of cycles; and every joint's transform
shares the rows of ``joints`` (what each layout cost: docs/performance.md,
"2026-11-26: the week's figures").

======================================  ==============================================
``cycle``                               every control cycle: per driven joint its
                                        reference, measured position, error, reference
                                        velocity, measured velocity and effort; per drive
                                        its motor torque; the loop's period and round
                                        trip (ms; NaN in lock-step): ``CycleSeries``
``drives/limits``                       each drive's peak torque, both ways, a row a
                                        second (the effort views draw it)
``drives/<actuator>/state``             the drive's state (StateChange, on change)
``bus/load``                            each bus' measured load, % of the bitrate per
                                        second of bus time (nominal and worst-case
                                        stuffing), and hil check's estimate
``loop/stalls/<process>``               a real-time process' stalls (sim, control,
                                        transport), a row a second at most: the worst's
                                        length (ms) where it began, and their count
``diagnostics``                         the controller's faults and resets (TextLog)
``robot/...``                           the URDF (rerun's UrdfTree)
``joints``                              every joint's transform (parent link to child),
                                        POSE_RATE rows a second per joint
``scene/<object>``                      a scene object of the bus config: its shape, and
                                        its pose (each sim clock tick for one that moves)
``scene/contacts``                      where things touch (points) and the force on the
                                        first of the two bodies (arrows, CONTACT_ARROW m/N)
``base``, ``base/position``             a floating base: the root link's frame in the
                                        world, and its position plotted
======================================  ==============================================

Several robots in one recording (``hil up ur3 pigot``): each robot's entities lie under
``/<robot>/`` (``/ur3/cycle``, the URDF at ``/ur3/visual_geometries/...``) and its URDF's
frames are named ``<robot>/<link>``, so robots with links of the same name never share a
frame.

Timelines: ``wall_time``; ``control_time`` (the controller's clock);
``sim_time`` (the plant's clock, found from the sim's clock pairs by
interpolation over wall time; absent while no sim has been heard).

Each job has its module, the recorder holding them and the recording's life cycle (the
static data, a batch, the grouped rows sent): :mod:`.cycles` (``cycle``), :mod:`.drives`
(``drives/...``), :mod:`.bus_load` (``bus/load``), :mod:`.events` (stalls, diagnostics),
:mod:`.poses` (``joints``), :mod:`.scene` (``scene/...``, ``base``).
"""

from __future__ import annotations

import time
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path

import rerun as rr
import rerun.blueprint as rrb
from rerun.urdf import UrdfTree

from hil.bus_config.types import SceneObject
from hil.can.monitor import MeasuredLoad
from hil.description import RobotDescription
from hil.messaging.diagnostics import DiagnosticStatus
from hil.messaging.samples import ControlSamples
from hil.messaging.scene import SceneState
from hil.messaging.sensors import ImuMessage, WrenchMessage
from hil.realtime.stalls import Stall
from hil.visualisation.blueprint import CycleSeries, robot_view
from hil.visualisation.bus_load import BusLoadLog
from hil.visualisation.columns import SimTimeMap
from hil.visualisation.entities import RobotEntities
from hil.visualisation.cycles import CycleRows
from hil.visualisation.drives import DriveStates, TorqueLimits
from hil.visualisation.events import EventLog
from hil.visualisation.poses import PoseLog
from hil.visualisation.scene import SceneLog
from hil.visualisation.sensors import SensorLog


@dataclass(frozen=True)
class BenchParts:
    """What a bus config adds to its robot that the recording draws: the scene, each drive's
    peak torque (by actuator, N·m), whether the base floats, each bus' estimated load
    (`hil check`'s worst case, a fraction of the bitrate: drawn beside the measured), and its
    sensors."""

    scene: tuple[SceneObject, ...] = ()
    torque_limits: Mapping[str, float] = field(default_factory=dict)
    floating_base: bool = False
    bus_estimates: Mapping[str, float] = field(default_factory=dict)
    #: its sensors, (name, kind: hil.messaging.zenoh_api's IMU or WRENCH) each
    sensors: tuple[tuple[str, str], ...] = ()


class RunRecorder:
    """Turns a robot's control samples and bus loads into rerun entities."""

    def __init__(self, recording: rr.RecordingStream, robot: RobotDescription,
                 urdf_path: Path, actuator_joints: dict[str, tuple[str, ...]],
                 buses: tuple[str, ...], namespaced: bool = False,
                 bench: BenchParts = BenchParts()):
        """``namespaced``: one of several robots in the recording (see the module doc);
        ``bench``: what the bus config adds to the robot."""
        self.recording = recording
        self.robot = robot
        self.sim_time = SimTimeMap()
        self.cycles_logged = 0
        self.cycles_lost = 0
        self._next_cycle: int | None = None
        #: where this robot's entities lie: "" (the recording's root) or "/<robot>"
        self.root = f"/{robot.name}" if namespaced else ""
        entities = RobotEntities(recording, self.root, self.sim_time)
        self._entities = entities
        self._urdf = (UrdfTree.from_file_path(urdf_path, None, frame_prefix=f"{robot.name}/",
                                              static_transform_entity_path=f"{self.root}/tf_static")
                      if namespaced else UrdfTree.from_file_path(urdf_path, "robot"))
        self._actuator_joints = actuator_joints
        self._buses = buses
        #: the bus monitor's name of each of this robot's buses: the bus' own, or
        #: "<robot>/<bus>" when namespaced (robots may have buses of the same name)
        self.monitor_names = {(f"{robot.name}/{bus}" if namespaced else bus): bus
                              for bus in buses}
        self._floating = bench.floating_base
        prefix = f"{robot.name}/" if namespaced else ""
        self.series = CycleSeries.of(robot, tuple(actuator_joints))
        self._cycles = CycleRows(entities, self.series)
        self._limits = TorqueLimits(entities, bench.torque_limits)
        self._states = DriveStates(entities)
        self._events = EventLog(entities)
        self._loads = BusLoadLog(entities, buses, self.monitor_names, bench.bus_estimates)
        # a floating base poses the URDF's root link's frame in the world
        self._scene = SceneLog(entities, bench.scene, prefix + self._urdf.root_link().name)
        self._poses = PoseLog(entities, robot, prefix)
        self._sensors = SensorLog(entities, bench.sensors)

    @property
    def stalls_logged(self) -> int:
        return self._events.stalls_logged

    def log_static(self) -> None:
        """The robot model and series names: before any sample, and again at the start of
        each segment of a recording (the drive states and the pose are then logged anew
        with the next batch, so that a segment opens alone)."""
        self._states.restart()
        self._poses.restart()
        self._urdf.log_urdf_to_recording(self.recording)
        self._cycles.log_static()
        self._limits.log_static()
        self._events.log_static()
        self._loads.log_static()
        self._scene.log_static()
        self._sensors.log_static()

    def view(self) -> rrb.Container:
        """This robot's part of the viewer's layout (``hil.visualisation.blueprint``)."""
        return robot_view(self.robot, self.series, self._actuator_joints, self._buses,
                          self.root, self._floating, tuple(self._limits.limits),
                          self._sensors.sensors)

    def log_clock(self, wall_time: float, sim_time: float) -> None:
        self.sim_time.add(wall_time, sim_time)

    def log_samples(self, batch: ControlSamples) -> None:
        """Log every cycle of a batch. Gaps in the cycle numbers are counted as lost."""
        if self._next_cycle is not None and batch.first_cycle > self._next_cycle:
            self.cycles_lost += batch.first_cycle - self._next_cycle
        self._next_cycle = batch.next_cycle
        self.cycles_logged += len(batch)
        times = self._entities.times(batch.wall_time, batch.control_time)
        self._loads.cycles(batch.wall_time, batch.period)
        self._cycles.log(batch, times)
        self._limits.log(times)
        self._states.log(batch, times)
        self._poses.log(batch, times)

    def log_diagnostic(self, diagnostic: DiagnosticStatus) -> None:
        """A fault (ERROR) or reset (OK) on the timelines, at the time the controller saw it."""
        self._events.diagnostic(diagnostic)

    def log_stall(self, stall: Stall) -> None:
        """A stall of a real-time process: gathered, a row an interval per process
        (:mod:`.stall_digest`) at the worst's start on the wall and sim timelines."""
        self._events.stall(stall)

    def log_bus_load(self, wall_time: float, loads: list[MeasuredLoad]) -> None:
        """The loads of this robot's buses among ``loads`` (named as ``monitor_names``),
        each measured over its interval up to ``wall_time``."""
        self._events.due(wall_time)     # a quiet process' last interval
        self._loads.add(wall_time, loads)

    def flush(self) -> None:
        """Send what waits to be grouped (the poses, the bus loads): before the recording
        is flushed, at a segment's end and at the end."""
        self._loads.send(time.time(), final=True)
        self._poses.send()
        self._events.drain()
        self._sensors.flush()

    def log_scene(self, state: SceneState) -> None:
        """The moving objects' poses, the contacts and a floating base's pose, at the state's
        wall and sim time."""
        self._scene.log(state)

    def log_sensor(self, message: ImuMessage | WrenchMessage) -> None:
        """A sensor's sample, at the time the controller received it."""
        self._sensors.log(message)
