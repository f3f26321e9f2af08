"""Logging a run into rerun: every axis on sim-time and wall-time timelines, the 3D robot.

Entities (a control batch's series go out as one Arrow record batch, which
rerun splits into one chunk per entity: one ``rr.log`` per scalar costs tens of
microseconds, one ``send_columns`` per entity about 200 us, the record batch
for all of them 1-3 ms per batch):

======================================  ==============================================
``axes/<joint>/position``               reference and measured position
``axes/<joint>/error``                  reference - measured
``axes/<joint>/velocity``               reference and measured velocity
``axes/<joint>/effort``                 joint-side effort (from the drive's torque)
``drives/<actuator>/torque``            motor torque as the drive reports it
``drives/<actuator>/state``             the drive's state (StateChange, on change)
``bus/<bus>/load``                      measured bus load, % of the bitrate
``loop/period_ms``, ``loop/round_trip_ms``  the control loop's period and round trip
``loop/stalls/<process>``               each stall of a real-time process (sim, control,
                                        transport): its length (ms) where it began
``diagnostics``                         the controller's faults and resets (TextLog)
``robot/...``, ``joints/<joint>``       the URDF (rerun's UrdfTree) and joint transforms
``scene/<object>``                      a scene object of the bus config: its shape, and
                                        its pose (each sim clock tick for one that moves)
``scene/contacts``                      where things touch (points) and the force on the
                                        first of the two bodies (arrows, CONTACT_ARROW m/N)
======================================  ==============================================

Several robots in one recording (``hil up ur3 pigot``): each robot's entities lie under
``/<robot>/`` (``/ur3/axes/joint1/position``, the URDF at ``/ur3/visual_geometries/...``)
and its URDF's frames are named ``<robot>/<link>``, so robots with links of the same name
never share a frame.

Timelines: ``wall_time``; ``control_time`` (the controller's clock);
``sim_time`` (the plant's clock, found from the sim's clock pairs by
interpolation over wall time; absent while no sim has been heard).
"""

from __future__ import annotations

from collections import deque
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pyarrow as pa
import rerun as rr
import rerun.blueprint as rrb
from rerun.urdf import UrdfTree

from hil.bus_config.types import SceneObject
from hil.can.monitor import MeasuredLoad
from hil.description import GeometryKind, RobotDescription
from hil.messaging.diagnostics import DiagnosticStatus
from hil.messaging.samples import ControlSamples
from hil.messaging.scene import SceneState
from hil.realtime.stalls import PROCESS_WORDS, Stall
from hil.visualisation.blueprint import robot_view

#: the 3D robot is posed at most this often (Hz): the eye needs no more
POSE_RATE = 30.0
#: contact force arrows: metres of arrow per newton (a 50 g object's weight: 25 mm)
CONTACT_ARROW = 0.05
#: a scene's plane is drawn as a square this wide (m): it is endless in the plant
PLANE_DRAWN = 4.0
#: diagnostic levels as rerun's text log levels
_TEXT_LOG_LEVELS = {"OK": rr.TextLogLevel.INFO, "WARN": rr.TextLogLevel.WARN,
                    "ERROR": rr.TextLogLevel.ERROR, "STALE": rr.TextLogLevel.WARN}


class SimTimeMap:
    """The plant's time at given wall-clock times, from (wall, sim) pairs the sim publishes.

    Inside the pairs: linear interpolation. After the last: extrapolated with
    the latest rate (1 in real time; the speed-up in lock-step).
    """

    def __init__(self, keep: int = 400):
        self._wall: deque[float] = deque(maxlen=keep)
        self._sim: deque[float] = deque(maxlen=keep)

    def add(self, wall: float, sim: float) -> None:
        if self._wall and wall <= self._wall[-1]:
            return
        if self._sim and sim < self._sim[-1]:       # the sim restarted: forget the old run
            self._wall.clear()
            self._sim.clear()
        self._wall.append(wall)
        self._sim.append(sim)

    def __call__(self, wall_times: np.ndarray) -> np.ndarray | None:
        if not self._wall:
            return None
        wall, sim = np.array(self._wall), np.array(self._sim)
        rate = 1.0 if len(wall) < 2 else (sim[-1] - sim[-2]) / (wall[-1] - wall[-2])
        mapped = np.interp(wall_times, wall, sim)
        after = wall_times > wall[-1]
        mapped[after] = sim[-1] + rate * (wall_times[after] - wall[-1])
        before = wall_times < wall[0]
        mapped[before] = sim[0] + (wall_times[before] - wall[0])
        return mapped


@dataclass(frozen=True)
class BenchParts:
    """What a bus config adds to its robot that the recording draws: the scene, each drive's
    peak torque (by actuator, N·m) and whether the base floats."""

    scene: tuple[SceneObject, ...] = ()
    torque_limits: Mapping[str, float] = field(default_factory=dict)
    floating_base: bool = False


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
        self.stalls_logged = 0
        self._next_cycle: int | None = None
        self._last_states: dict[str, str] = {}
        self._last_pose = -np.inf
        #: where this robot's entities lie: "" (the recording's root) or "/<robot>"
        self.root = f"/{robot.name}" if namespaced else ""
        self._urdf = (UrdfTree.from_file_path(urdf_path, None, frame_prefix=f"{robot.name}/",
                                              static_transform_entity_path=f"{self.root}/tf_static")
                      if namespaced else UrdfTree.from_file_path(urdf_path, "robot"))
        self._actuator_joints = actuator_joints
        self._buses = buses
        #: the bus monitor's name of each of this robot's buses: the bus' own, or
        #: "<robot>/<bus>" when namespaced (robots may have buses of the same name)
        self.monitor_names = {(f"{robot.name}/{bus}" if namespaced else bus): bus
                              for bus in buses}
        self._mimics = {j.name: j.mimic for j in robot.joints if j.mimic is not None}
        self._scene = bench.scene
        self._torque_limits = bench.torque_limits
        self._floating = bench.floating_base
        root_link = self._urdf.root_link().name
        #: the frame a floating base poses in the world (the URDF's root link's)
        self._base_frame = f"{robot.name}/{root_link}" if namespaced else root_link

    def log_static(self) -> None:
        """The robot model and series names; once, before any sample."""
        rec, root = self.recording, self.root
        self._urdf.log_urdf_to_recording(rec)
        for joint in self.robot.driven_joints:
            unit = joint.type.unit
            rec.log(f"{root}/axes/{joint.name}/position",
                    rr.SeriesLines(names=[f"reference [{unit}]", f"measured [{unit}]"]),
                    static=True)
            rec.log(f"{root}/axes/{joint.name}/error", rr.SeriesLines(names=[f"error [{unit}]"]),
                    static=True)
            rec.log(f"{root}/axes/{joint.name}/velocity",
                    rr.SeriesLines(names=[f"reference [{unit}/s]", f"measured [{unit}/s]"]),
                    static=True)
            rec.log(f"{root}/axes/{joint.name}/effort",
                    rr.SeriesLines(names=[f"joint effort [{joint.type.effort_unit}]"]),
                    static=True)
        for actuator in self._actuator_joints:
            rec.log(f"{root}/drives/{actuator}/torque", rr.SeriesLines(names=["motor torque [N·m]"]),
                    static=True)
            if actuator in self._torque_limits:
                rec.log(f"{root}/drives/{actuator}/torque_limit", rr.SeriesLines(
                    names=["peak torque [N·m]", "-peak torque [N·m]"],
                    colors=[[200, 60, 60], [200, 60, 60]], widths=[0.5, 0.5]), static=True)
        for process, words in PROCESS_WORDS.items():     # points: a stall is an event
            rec.log(f"{root}/loop/stalls/{process}", rr.SeriesPoints(
                names=[f"{words} stalled [ms]"], markers=["cross"], marker_sizes=[6.0]),
                static=True)
        for bus in self._buses:
            rec.log(f"{root}/bus/{bus}/load",
                    rr.SeriesLines(names=["load [%]", "load, worst-case stuffing [%]"]),
                    static=True)
        for thing in self._scene:
            rec.log(f"{root}/scene/{thing.name}", _shape(thing), static=True)
            if not thing.movable:       # a moving one is posed by each SceneState
                rec.log(f"{root}/scene/{thing.name}", rr.Transform3D(
                    translation=thing.pose.xyz,
                    quaternion=rr.Quaternion(xyzw=_quaternion(thing.pose.rpy))), static=True)

    def view(self) -> rrb.Container:
        """This robot's part of the viewer's layout (``hil.visualisation.blueprint``)."""
        return robot_view(self.robot, self._actuator_joints, self._buses, self.root,
                          self._floating)

    def log_clock(self, wall_time: float, sim_time: float) -> None:
        self.sim_time.add(wall_time, sim_time)

    def log_samples(self, batch: ControlSamples) -> None:
        """Log every cycle of a batch. Gaps in the cycle numbers are counted as lost."""
        if self._next_cycle is not None and batch.first_cycle > self._next_cycle:
            self.cycles_lost += batch.first_cycle - self._next_cycle
        self._next_cycle = batch.next_cycle
        self.cycles_logged += len(batch)
        times = self._times(batch.wall_time, batch.control_time)
        table = _ScalarTable(times)
        for i, joint in enumerate(batch.joint_names):
            reference, position = batch.reference[:, i], batch.position[:, i]
            table.add(f"{self.root}/axes/{joint}/position", reference, position)
            table.add(f"{self.root}/axes/{joint}/error", reference - position)
            table.add(f"{self.root}/axes/{joint}/velocity", batch.reference_velocity[:, i],
                      batch.velocity[:, i])
            table.add(f"{self.root}/axes/{joint}/effort", batch.effort[:, i])
        for k, actuator in enumerate(batch.actuator_names):
            table.add(f"{self.root}/drives/{actuator}/torque", batch.motor_torque[:, k])
        self._log_torque_limits(times)
        if not np.isnan(batch.cycle_period).all():       # real time: the loop's own timing
            table.add(f"{self.root}/loop/period_ms", 1e3 * batch.cycle_period)
            table.add(f"{self.root}/loop/round_trip_ms", 1e3 * batch.round_trip)
        table.send(self.recording)
        for k, actuator in enumerate(batch.actuator_names):
            self._log_state_changes(actuator, batch, k, times)
        self._log_pose(batch, times)

    def log_diagnostic(self, diagnostic: DiagnosticStatus) -> None:
        """A fault (ERROR) or reset (OK) on the timelines, at the time the controller saw it."""
        control = None if diagnostic.control_time is None else np.array([diagnostic.control_time])
        times = self._times(np.array([diagnostic.wall_time]), control)
        self.recording.send_columns(
            f"{self.root}/diagnostics", indexes=times.columns(),
            columns=rr.TextLog.columns(text=[diagnostic.message],
                                       level=[_TEXT_LOG_LEVELS[diagnostic.level]]))

    def log_stall(self, stall: Stall) -> None:
        """A stall of a real-time process on the wall and sim timelines, where it began."""
        table = _ScalarTable(self._times(np.array([stall.at])))
        table.add(f"{self.root}/loop/stalls/{stall.process}", np.array([stall.length * 1e3]))
        table.send(self.recording)
        self.stalls_logged += 1

    def log_bus_load(self, wall_time: float, loads: list[MeasuredLoad]) -> None:
        """The loads of this robot's buses among ``loads`` (named as ``monitor_names``)."""
        mine = [(self.monitor_names[load.bus], load) for load in loads
                if load.bus in self.monitor_names]
        if not mine:
            return
        table = _ScalarTable(self._times(np.array([wall_time])))
        for bus, load in mine:
            table.add(f"{self.root}/bus/{bus}/load", np.array([100 * load.nominal]),
                      np.array([100 * load.worst_case]))
        table.send(self.recording)

    def log_scene(self, state: SceneState) -> None:
        """The moving objects' poses, the contacts and a floating base's pose, at the state's
        wall and sim time."""
        times = _Times(np.array([state.wall_time]), None, np.array([state.sim_time]))
        indexes = times.columns()
        rec, root = self.recording, self.root
        if state.base is not None:
            position, orientation = state.base
            # the robot's root frame, placed in the recording's own (its entities' root)
            rec.send_columns(f"{root}/base", indexes=indexes, columns=rr.Transform3D.columns(
                translation=[position], quaternion=[np.roll(orientation, -1)],
                parent_frame=["tf#/"], child_frame=[self._base_frame]))
            table = _ScalarTable(times)
            table.add(f"{root}/base/position", *position.reshape(3, 1))
            table.send(rec)
        for name, position, orientation in zip(state.names, state.positions,
                                               state.orientations):
            rec.send_columns(f"{root}/scene/{name}", indexes=indexes,
                             columns=rr.Transform3D.columns(
                                 translation=[position],
                                 quaternion=[np.roll(orientation, -1)]))     # w first -> last
        rec.send_columns(f"{root}/scene/contacts", indexes=indexes, columns=[
            *rr.Points3D.columns(positions=state.contact_points).partition([
                len(state.contact_points)]),
            *rr.Arrows3D.columns(origins=state.contact_points,
                                 vectors=CONTACT_ARROW * state.contact_forces).partition([
                len(state.contact_points)])])

    # --- helpers -----------------------------------------------------------------------

    def _log_torque_limits(self, times: _Times) -> None:
        """Each drive's peak torque, both ways, at a batch's first and last rows: a line
        beside its torque, at a byte cost per batch, not per cycle."""
        if not self._torque_limits:
            return
        table = _ScalarTable(times.at(np.array([0, len(times.wall) - 1])))
        for actuator, limit in self._torque_limits.items():
            table.add(f"{self.root}/drives/{actuator}/torque_limit", np.full(2, limit),
                      np.full(2, -limit))
        table.send(self.recording)

    def _times(self, wall: np.ndarray, control: np.ndarray | None = None) -> _Times:
        return _Times(wall, control, self.sim_time(wall))

    def _log_state_changes(self, actuator: str, batch: ControlSamples, column: int,
                           times: _Times) -> None:
        codes = batch.drive_state[:, column]
        if not len(codes):
            return
        rows = np.flatnonzero(np.diff(codes)) + 1
        if batch.state_names[codes[0]] != self._last_states.get(actuator):
            rows = np.concatenate(([0], rows))
        self._last_states[actuator] = batch.state_names[codes[-1]]
        if len(rows):
            self.recording.send_columns(
                f"{self.root}/drives/{actuator}/state", indexes=times.columns(rows),
                columns=rr.StateChange.columns(state=[batch.state_names[c] for c in codes[rows]]))

    def _log_pose(self, batch: ControlSamples, times: _Times) -> None:
        """Joint transforms for the 3D robot, decimated to POSE_RATE."""
        wall = batch.wall_time
        rows = []
        for row, t in enumerate(wall):
            if t - self._last_pose >= 1.0 / POSE_RATE:
                rows.append(row)
                self._last_pose = t
        if not rows:
            return
        rows = np.array(rows)
        positions = dict(zip(batch.joint_names, batch.position[rows].T))
        for name, mimic in self._mimics.items():
            if mimic.joint in positions:
                positions[name] = mimic.multiplier * positions[mimic.joint] + mimic.offset
        selected = times.columns(rows)
        for name, values in positions.items():
            joint = self._urdf.get_joint_by_name(name)
            if joint is not None:
                self.recording.send_columns(
                    f"{self.root}/joints/{name}", indexes=selected,
                    columns=joint.compute_transform_columns(values, clamp=False))


def _shape(thing: SceneObject) -> rr.AsComponents:
    """The rerun archetype that draws a scene object's shape, in its own frame."""
    geometry = thing.geometry
    size = geometry.size
    if geometry.kind is GeometryKind.BOX:
        return rr.Boxes3D(half_sizes=[[s / 2 for s in size]])
    if geometry.kind is GeometryKind.SPHERE:
        return rr.Ellipsoids3D(half_sizes=[[size[0]] * 3])
    if geometry.kind is GeometryKind.CYLINDER:
        return rr.Cylinders3D(lengths=[size[1]], radii=[size[0]])
    if geometry.kind is GeometryKind.MESH:
        return rr.Asset3D(path=geometry.mesh)
    return rr.Boxes3D(half_sizes=[[PLANE_DRAWN / 2, PLANE_DRAWN / 2, 0.0005]],
                      centers=[[0.0, 0.0, -0.0005]], colors=[[128, 128, 128, 96]])


def _quaternion(rpy) -> np.ndarray:
    """Roll-pitch-yaw (fixed X, Y, Z) as a quaternion x, y, z, w (rerun's order)."""
    roll, pitch, yaw = (angle / 2 for angle in rpy)
    cr, sr, cp, sp, cy, sy = (np.cos(roll), np.sin(roll), np.cos(pitch), np.sin(pitch),
                              np.cos(yaw), np.sin(yaw))
    return np.array([sr * cp * cy - cr * sp * sy, cr * sp * cy + sr * cp * sy,
                     cr * cp * sy - sr * sp * cy, cr * cp * cy + sr * sp * sy])


@dataclass(frozen=True)
class _Times:
    """The times of a batch's rows on each timeline (sim time may be unknown)."""

    wall: np.ndarray
    control: np.ndarray | None
    sim: np.ndarray | None

    def at(self, rows: np.ndarray) -> _Times:
        """These times at ``rows`` only."""
        return _Times(self.wall[rows], None if self.control is None else self.control[rows],
                      None if self.sim is None else self.sim[rows])

    def named(self) -> list[tuple[str, np.ndarray]]:
        return [(name, values) for name, values in (("wall_time", self.wall),
                                                    ("control_time", self.control),
                                                    ("sim_time", self.sim))
                if values is not None]

    def columns(self, rows: np.ndarray | slice = slice(None)) -> list[rr.TimeColumn]:
        columns = [rr.TimeColumn("wall_time", timestamp=self.wall[rows])]
        if self.control is not None:
            columns.append(rr.TimeColumn("control_time", duration=self.control[rows]))
        if self.sim is not None:
            columns.append(rr.TimeColumn("sim_time", duration=self.sim[rows]))
        return columns


class _ScalarTable:
    """Scalar series of many entities on the same rows, sent as one Arrow record batch.

    The ``rerun:*`` field metadata is rerun's documented column classification
    (``Chunk.from_record_batch``): which columns are timelines, and which entity
    and component every other column is.
    """

    def __init__(self, times: _Times):
        self._fields, self._columns = [], []
        for name, values in times.named():
            kind = pa.timestamp("ns") if name == "wall_time" else pa.duration("ns")
            self._fields.append(pa.field(name, kind, metadata={
                "rerun:kind": "index", "rerun:index_name": name}))
            self._columns.append(pa.array(np.round(values * 1e9).astype(np.int64), kind))

    def add(self, entity: str, *series: np.ndarray) -> None:
        """One row per time, one scalar per series (as many series as lines on the plot)."""
        values = np.column_stack(series).ravel() if len(series) > 1 else series[0]
        self._fields.append(pa.field("Scalars:scalars", pa.list_(pa.float64()), metadata={
            "rerun:kind": "data", "rerun:entity_path": entity,
            "rerun:archetype": "rerun.archetypes.Scalars", "rerun:component": "Scalars:scalars",
            "rerun:component_type": "rerun.components.Scalar"}))
        offsets = np.arange(0, len(values) + 1, len(series), dtype=np.int32)
        self._columns.append(pa.ListArray.from_arrays(pa.array(offsets),
                                                      pa.array(values, pa.float64())))

    def send(self, recording: rr.RecordingStream) -> None:
        rr.send_record_batch(pa.RecordBatch.from_arrays(self._columns,
                                                        schema=pa.schema(self._fields)),
                             recording=recording)
