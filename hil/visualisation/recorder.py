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
"""

from __future__ import annotations

import time
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
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
from hil.visualisation.bus_time import BusTimeLoads
from hil.visualisation.stall_digest import StallDigest, StallRow
from hil.description.rotations import rpy_quaternion
from hil.visualisation.blueprint import CycleSeries, robot_view
from hil.visualisation.columns import ScalarTable, SimTimeMap, Times
from hil.visualisation.kinematics import JointPoses

#: the 3D robot is posed at most this often (Hz): the eye needs no more
POSE_RATE = 20.0
#: each drive's peak torque is logged this often (s): a line needs no more
LIMITS_EVERY = 1.0
#: the poses and the bus loads are sent in chunks of this many seconds: rerun's file sink
#: keeps an index entry per chunk (and per column of it) until the file is closed, so a
#: chunk of each every 100 ms grew the visualiser's memory without end (docs/performance.md,
#: "2026-11-26: the week's figures")
GROUPED = 0.5
#: contact force arrows: metres of arrow per newton (a 50 g object's weight: 25 mm)
CONTACT_ARROW = 0.05
#: a scene's plane is drawn as a square this wide (m): it is endless in the plant
PLANE_DRAWN = 4.0
#: diagnostic levels as rerun's text log levels
_TEXT_LOG_LEVELS = {"OK": rr.TextLogLevel.INFO, "WARN": rr.TextLogLevel.WARN,
                    "ERROR": rr.TextLogLevel.ERROR, "STALE": rr.TextLogLevel.WARN}


@dataclass(frozen=True)
class BenchParts:
    """What a bus config adds to its robot that the recording draws: the scene, each drive's
    peak torque (by actuator, N·m), whether the base floats, and each bus' estimated load
    (`hil check`'s worst case, a fraction of the bitrate: drawn beside the measured)."""

    scene: tuple[SceneObject, ...] = ()
    torque_limits: Mapping[str, float] = field(default_factory=dict)
    floating_base: bool = False
    bus_estimates: Mapping[str, float] = field(default_factory=dict)


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
        self._bus_estimates = bench.bus_estimates
        self._stalls = StallDigest()
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
        self._scene = bench.scene
        self._torque_limits = dict(bench.torque_limits)
        self._limits_logged = -np.inf
        self._floating = bench.floating_base
        prefix = f"{robot.name}/" if namespaced else ""
        #: the frame a floating base poses in the world (the URDF's root link's)
        self._base_frame = prefix + self._urdf.root_link().name
        self.series = CycleSeries.of(robot, tuple(actuator_joints))
        self._columns: dict[tuple, np.ndarray] = {}    # a batch's layout: where each goes
        self._poses = JointPoses(robot, prefix)
        #: what waits to be sent in GROUPED chunks: (wall time, bus loads) rows, and poses
        #: (times, translations, quaternions, parent and child frames)
        self._loads = BusTimeLoads()
        self._loads_sent = -np.inf
        self._poses_waiting: list[tuple] = []

    def log_static(self) -> None:
        """The robot model and series names: before any sample, and again at the start of
        each segment of a recording (the drive states and the pose are then logged anew
        with the next batch, so that a segment opens alone)."""
        self._last_states.clear()
        self._last_pose = -np.inf
        rec, root = self.recording, self.root
        self._urdf.log_urdf_to_recording(rec)
        rec.log(f"{root}/cycle", rr.SeriesLines(names=self.series.names()), static=True)
        if self._torque_limits:
            rec.log(f"{root}/drives/limits", rr.SeriesLines(
                names=[f"{actuator} {sign}peak [N·m]" for actuator in self._torque_limits
                       for sign in "+-"]), static=True)
        self._limits_logged = -np.inf
        for process, words in PROCESS_WORDS.items():     # points: a stall is an event
            rec.log(f"{root}/loop/stalls/{process}", rr.SeriesPoints(
                names=[f"{words} stalled [ms], the second's worst",
                       f"{words} stalls that second"],
                markers=["cross", "circle"], marker_sizes=[6.0, 3.0]), static=True)
        rec.log(f"{root}/bus/load", rr.SeriesLines(names=[
            f"{bus} {what} [%]" for bus in self._buses
            for what in ("load", "load, worst-case stuffing", "hil check's worst case")]),
            static=True)
        for thing in self._scene:
            rec.log(f"{root}/scene/{thing.name}", _shape(thing), static=True)
            if not thing.movable:       # a moving one is posed by each SceneState
                rec.log(f"{root}/scene/{thing.name}", rr.Transform3D(
                    translation=thing.pose.xyz,
                    quaternion=rr.Quaternion(xyzw=rpy_quaternion(thing.pose.rpy))), static=True)

    def view(self) -> rrb.Container:
        """This robot's part of the viewer's layout (``hil.visualisation.blueprint``)."""
        return robot_view(self.robot, self.series, self._actuator_joints, self._buses,
                          self.root, self._floating, tuple(self._torque_limits))

    def log_clock(self, wall_time: float, sim_time: float) -> None:
        self.sim_time.add(wall_time, sim_time)

    def log_samples(self, batch: ControlSamples) -> None:
        """Log every cycle of a batch. Gaps in the cycle numbers are counted as lost."""
        if self._next_cycle is not None and batch.first_cycle > self._next_cycle:
            self.cycles_lost += batch.first_cycle - self._next_cycle
        self._next_cycle = batch.next_cycle
        self.cycles_logged += len(batch)
        times = self._times(batch.wall_time, batch.control_time)
        self._loads.cycles(batch.wall_time, batch.period)
        table = ScalarTable(times)
        table.add_rows(f"{self.root}/cycle", self._cycle_rows(batch))
        table.send(self.recording)
        self._log_torque_limits(times)
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
        """A stall of a real-time process: gathered, a row an interval per process
        (:mod:`.stall_digest`) at the worst's start on the wall and sim timelines."""
        self.stalls_logged += 1
        self._send_stalls(self._stalls.add(stall))

    def _send_stalls(self, rows: list[StallRow]) -> None:
        for row in rows:
            table = ScalarTable(self._times(np.array([row.at])))
            table.add(f"{self.root}/loop/stalls/{row.process}", np.array([row.worst * 1e3]),
                      np.array([float(row.count)]))
            table.send(self.recording)

    def log_bus_load(self, wall_time: float, loads: list[MeasuredLoad]) -> None:
        """The loads of this robot's buses among ``loads`` (named as ``monitor_names``),
        each measured over its interval up to ``wall_time``."""
        self._send_stalls(self._stalls.due(wall_time))     # a quiet process' last interval
        by_bus = {self.monitor_names[load.bus]: load for load in loads
                  if load.bus in self.monitor_names}
        row = [100 * value for bus in self._buses if bus in by_bus
               for value in (by_bus[bus].nominal, by_bus[bus].worst_case)]
        if len(row) != 2 * len(self._buses):          # a bus not measured: none this time
            return
        interval = max(load.interval for load in by_bus.values())
        self._loads.add(wall_time - interval, wall_time, row)
        if wall_time - self._loads_sent >= GROUPED:
            self._send_loads(wall_time)

    def _send_loads(self, now: float, final: bool = False) -> None:
        """The bus-load rows ready (on bus time: :mod:`.bus_time`), as one chunk."""
        self._loads_sent = now
        times, rows = self._loads.ready(now, final)
        if not rows:
            return
        measured = np.array(rows, dtype=np.float32).reshape(len(rows), -1, 2)
        estimates = np.array([100 * self._bus_estimates.get(bus, np.nan) for bus in self._buses],
                             dtype=np.float32)          # beside each bus' pair, unscaled
        table = ScalarTable(self._times(np.array(times)))
        table.add_rows(f"{self.root}/bus/load", np.concatenate(
            (measured, np.broadcast_to(estimates[None, :, None], (len(rows), len(estimates), 1))),
            axis=2).reshape(len(rows), -1))
        table.send(self.recording)

    def flush(self) -> None:
        """Send what waits to be grouped (the poses, the bus loads): before the recording
        is flushed, at a segment's end and at the end."""
        self._send_loads(time.time(), final=True)
        self._send_poses()
        self._send_stalls(self._stalls.drain())

    def log_scene(self, state: SceneState) -> None:
        """The moving objects' poses, the contacts and a floating base's pose, at the state's
        wall and sim time."""
        times = Times(np.array([state.wall_time]), None, np.array([state.sim_time]))
        indexes = times.columns()
        rec, root = self.recording, self.root
        if state.base is not None:
            position, orientation = state.base
            # the robot's root frame, placed in the recording's own (its entities' root)
            rec.send_columns(f"{root}/base", indexes=indexes, columns=rr.Transform3D.columns(
                translation=[position], quaternion=[np.roll(orientation, -1)],
                parent_frame=["tf#/"], child_frame=[self._base_frame]))
            table = ScalarTable(times)
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

    def _cycle_rows(self, batch: ControlSamples) -> np.ndarray:
        """The batch's cycles as the rows of ``cycle`` (float32, CycleSeries' order)."""
        layout = (batch.joint_names, batch.actuator_names)
        columns = self._columns.get(layout)
        if columns is None:          # where each joint's and actuator's column of the batch goes
            joints = [batch.joint_names.index(j) for j in self.series.joints]
            actuators = [batch.actuator_names.index(a) for a in self.series.actuators]
            columns = self._columns[layout] = (np.array(joints), np.array(actuators))
        joints, actuators = columns
        reference, position = batch.reference[:, joints], batch.position[:, joints]
        per_joint = np.stack((reference, position, reference - position,
                              batch.reference_velocity[:, joints], batch.velocity[:, joints],
                              batch.effort[:, joints]), axis=2).reshape(len(batch), -1)
        return np.hstack((per_joint, batch.motor_torque[:, actuators],
                          1e3 * batch.cycle_period[:, None],
                          1e3 * batch.round_trip[:, None])).astype(np.float32)

    def _log_torque_limits(self, times: Times) -> None:
        """Each drive's peak torque, both ways, a row every LIMITS_EVERY s (at the batch's
        first cycle): a line beside its torque, at the bytes of a few rows a minute."""
        if not self._torque_limits or times.wall[0] - self._limits_logged < LIMITS_EVERY:
            return
        self._limits_logged = times.wall[0]
        table = ScalarTable(times.at(np.array([0])))
        table.add_rows(f"{self.root}/drives/limits", np.array(
            [[sign * limit for limit in self._torque_limits.values() for sign in (1, -1)]],
            dtype=np.float32))
        table.send(self.recording)

    def _times(self, wall: np.ndarray, control: np.ndarray | None = None) -> Times:
        return Times(wall, control, self.sim_time(wall))

    def _log_state_changes(self, actuator: str, batch: ControlSamples, column: int,
                           times: Times) -> None:
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

    def _log_pose(self, batch: ControlSamples, times: Times) -> None:
        """Joint transforms for the 3D robot, decimated to POSE_RATE, every joint's in the
        rows of one entity (each row a parent-to-child transform, as rerun's tf reads it)."""
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
        translations, quaternions, parents, children = self._poses.transforms(positions)
        count = len(translations) // len(rows)              # joints posed per row
        self._poses_waiting.append((times.at(np.repeat(rows, count)), translations, quaternions,
                                    parents, children))
        if wall[rows[-1]] - self._poses_waiting[0][0].wall[0] >= GROUPED:
            self._send_poses()

    def _send_poses(self) -> None:
        waiting = self._poses_waiting
        if not waiting:
            return
        times = Times(np.concatenate([t.wall for t, *_ in waiting]),
                       _joined([t.control for t, *_ in waiting]),
                       _joined([t.sim for t, *_ in waiting]))
        self.recording.send_columns(
            f"{self.root}/joints", indexes=times.columns(), columns=rr.Transform3D.columns(
                translation=np.concatenate([w[1] for w in waiting]),
                quaternion=np.concatenate([w[2] for w in waiting]),
                parent_frame=[p for w in waiting for p in w[3]],
                child_frame=[c for w in waiting for c in w[4]]))
        waiting.clear()


def _joined(parts: list[np.ndarray | None]) -> np.ndarray | None:
    """Arrays of one timeline joined; None where any part lacks it (the first poses before
    the sim's clock was heard have no sim time: their group then has none)."""
    return None if any(p is None for p in parts) else np.concatenate(parts)


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
