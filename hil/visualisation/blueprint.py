"""The rerun layout of a run: the 3D robot, drive states, bus load and the control loop's
timing beside one time-series view per axis (position, velocity, effort tabs), so that
six axes read at a glance; several robots get a tab each.

Every control cycle of a robot is one row of one entity, ``cycle`` (:class:`CycleSeries`:
rows shared by every signal cost their row id and times once, not once a signal); each
per-axis view shows its own few of that entity's series (rerun's ``visible_series``,
overridden per view, the others unnamed so that its legend lists only its own)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import rerun as rr
import rerun.blueprint as rrb

from hil.description import RobotDescription
from hil.description.rotations import rpy_matrix
from hil.messaging.keys import IMU
from hil.visualisation.sensors import QUANTITIES

#: a joint's series in ``cycle``, in order, and their units by joint type
JOINT_SERIES = ("reference", "measured", "error", "reference velocity", "velocity", "effort")
#: the control loop's series after the joints' and the drives' (ms; NaN in lock-step)
LOOP_SERIES = ("period [ms]", "round trip [ms]")
#: the colours of the series in their views: reference grey, measured blue, error red;
#: velocity the same; effort orange and the drive's torque purple; the loop's period blue,
#: its round trip orange
_COLOURS = {"reference": (150, 150, 150), "measured": (80, 160, 255), "error": (240, 80, 80),
            "reference velocity": (150, 150, 150), "velocity": (80, 200, 120),
            "effort": (255, 160, 40), "torque": (190, 110, 255),
            "period [ms]": (80, 160, 255), "round trip [ms]": (255, 160, 40)}


@dataclass(frozen=True)
class CycleSeries:
    """The series of a robot's ``cycle`` entity: per driven joint JOINT_SERIES, then per
    actuator its motor torque, then LOOP_SERIES."""

    joints: tuple[str, ...]
    units: tuple[tuple[str, str], ...]       # per joint: position unit, effort unit
    actuators: tuple[str, ...]

    @classmethod
    def of(cls, robot: RobotDescription, actuators: tuple[str, ...]) -> CycleSeries:
        joints = robot.driven_joints
        return cls(tuple(j.name for j in joints),
                   tuple((j.type.unit, j.type.effort_unit) for j in joints), actuators)

    def __len__(self) -> int:
        return len(self.joints) * len(JOINT_SERIES) + len(self.actuators) + len(LOOP_SERIES)

    def joint(self, joint: str, quantity: str) -> int:
        return self.joints.index(joint) * len(JOINT_SERIES) + JOINT_SERIES.index(quantity)

    def torque(self, actuator: str) -> int:
        return len(self.joints) * len(JOINT_SERIES) + self.actuators.index(actuator)

    def loop(self, quantity: str) -> int:
        return len(self) - len(LOOP_SERIES) + LOOP_SERIES.index(quantity)

    def names(self) -> list[str]:
        """Each series' name, with its unit."""
        names = []
        for joint, (unit, effort) in zip(self.joints, self.units):
            names += [f"{joint} reference [{unit}]", f"{joint} measured [{unit}]",
                      f"{joint} error [{unit}]", f"{joint} reference velocity [{unit}/s]",
                      f"{joint} velocity [{unit}/s]", f"{joint} effort [{effort}]"]
        names += [f"{actuator} torque [N·m]" for actuator in self.actuators]
        return names + list(LOOP_SERIES)

    def showing(self, shown: dict[int, str]) -> rr.SeriesLines:
        """The override that makes a view of ``cycle`` show the series ``shown`` (index:
        colour key) and name only those."""
        names = self.names()
        return rr.SeriesLines(
            visible_series=[k in shown for k in range(len(self))],
            names=[names[k] if k in shown else "" for k in range(len(self))],
            colors=[_COLOURS[shown[k]] if k in shown else (0, 0, 0) for k in range(len(self))])


def robot_view(robot: RobotDescription, series: CycleSeries,
               actuator_joints: dict[str, tuple[str, ...]], buses: tuple[str, ...],
               root: str = "", floating_base: bool = False, limits: tuple[str, ...] = (),
               sensors: tuple[tuple[str, str], ...] = ()) -> rrb.Container:
    """One robot's layout, its entities under ``root`` ("" or "/<robot>", as
    ``RunRecorder.root``); ``limits``: the actuators whose peak torque is drawn (in
    ``drives/limits``, two series each, in that order); the diagnostics, a floating
    base's position and each of ``sensors`` ((name, kind) each) are tabs beside the drive
    states."""
    cycle = f"{root}/cycle"
    actuators_of = {j: [a for a, js in actuator_joints.items() if j in js]
                    for j in series.joints}

    def view(name: str, shown) -> rrb.TimeSeriesView:
        # the legend hidden: a joint's small plot shows two or three series, their colours
        # the same in every plot and named in the tab's title (it covered 40 % of the data)
        contents, overrides = shown
        return rrb.TimeSeriesView(name=name, origin="/", contents=contents, overrides=overrides,
                                  plot_legend=rrb.PlotLegend(visible=False))

    def grid(name: str, shown_of) -> rrb.Grid:
        return rrb.Grid(*(view(joint, shown_of(joint)) for joint in series.joints), name=name)

    def tracking(joint: str) -> rrb.Vertical:
        """The position beside its error, each on its own scale (mrad on the position's
        is a flat line)."""
        return rrb.Vertical(view(joint, kinds(joint, ("reference", "measured"))),
                            view(f"{joint} error", kinds(joint, ("error",))), row_shares=[2, 1])

    def kinds(joint: str, quantities: tuple[str, ...]):
        return [cycle], {cycle: series.showing({series.joint(joint, q): q
                                                for q in quantities})}

    def efforts(joint: str):
        shown = {series.joint(joint, "effort"): "effort"}
        shown.update({series.torque(a): "torque" for a in actuators_of[joint]
                      if a in series.actuators})
        overrides = {cycle: series.showing(shown)}
        drawn = [a for a in actuators_of[joint] if a in limits]
        if drawn:
            overrides[f"{root}/drives/limits"] = rr.SeriesLines(
                visible_series=[a in drawn for a in limits for _ in (1, -1)],
                names=[f"{a} {'+' if sign > 0 else '-'}peak [N·m]" if a in drawn else ""
                       for a in limits for sign in (1, -1)],
                colors=[(200, 60, 60)] * 2 * len(limits))
        return [cycle, f"{root}/drives/limits"], overrides

    axes = rrb.Tabs(
        rrb.Grid(*(tracking(joint) for joint in series.joints),
                 name="position: reference, measured; error"),
        grid("velocity: reference, measured", lambda j: kinds(j, ("reference velocity",
                                                                  "velocity"))),
        grid("effort: joint effort, motor torque, peak", efforts),
    )
    model = ([f"{root}/visual_geometries/**", f"{root}/collision_geometries/**"] if root
             else ["/robot/**"])
    # the controller's faults and resets beside the drive states: a click on one puts the
    # timelines at it (a long run's fault in one step)
    states = [rrb.StateTimelineView(name="drive states", origin=f"{root}/drives"),
              rrb.TextLogView(name="diagnostics", origin=f"{root}/diagnostics")]
    if floating_base:
        states.append(rrb.TimeSeriesView(name="base position [m]", origin=f"{root}/base",
                                         contents=[f"{root}/base/position"]))
    for sensor, kind in sensors:    # a sensor's tab: its quantities, each on its scale
        origin = f"{root}/sensors/{sensor}"
        states.append(rrb.Vertical(*(
            rrb.TimeSeriesView(name=f"{quantity.replace('_', ' ')} [{unit}]",
                               origin=f"{origin}/{quantity}")
            for quantity, _, unit in QUANTITIES[kind]),
            name=f"{'IMU' if kind == IMU else 'force-torque'} {sensor}"))
    loop = {series.loop(q): q for q in LOOP_SERIES}
    hidden = rrb.PlotLegend(visible=False)      # the views' names say what they show
    side = rrb.Vertical(
        rrb.Spatial3DView(name=robot.name, origin="/", contents=[
            *model, f"{root}/joints", f"{root}/scene/**", f"{root}/base"],
            eye_controls=framing(robot)),
        rrb.Tabs(*states),
        rrb.TimeSeriesView(name="bus load [%]: nominal, worst-case stuffing, hil check's",
                           origin=f"{root}/bus", contents=[f"{root}/bus/load"],
                           plot_legend=hidden),
        rrb.TimeSeriesView(name="control loop [ms]: period, round trip, stalls",
                           origin=f"{root}/loop", contents=[cycle, f"{root}/loop/stalls/**"],
                           overrides={cycle: series.showing(loop)}, plot_legend=hidden),
        row_shares=[2.5, 3, 1, 1],        # every drive's state lane readable
    )
    return rrb.Horizontal(side, axes, column_shares=[2, 3], name=robot.name)


def framing(robot: RobotDescription) -> rrb.EyeControls3D:
    """A camera on the whole robot as it stands at zero: its links' origins' box seen from
    the front right, above, from far enough that the box fits."""
    placed = {robot.root_link: (np.eye(3), np.zeros(3))}
    pending = list(robot.joints)
    while pending:                                  # parents before children
        waiting = []
        for joint in pending:
            if joint.parent not in placed:
                waiting.append(joint)
                continue
            rotation, position = placed[joint.parent]
            placed[joint.child] = (rotation @ np.array(rpy_matrix(joint.origin.rpy)).reshape(3, 3),
                                   position + rotation @ np.array(joint.origin.xyz))
        if len(waiting) == len(pending):           # joints of links off the tree: left out
            break
        pending = waiting
    points = np.array([position for _, position in placed.values()])
    low, high = points.min(axis=0), points.max(axis=0)
    centre, size = (low + high) / 2, max(float(np.max(high - low)), 0.3)
    return rrb.EyeControls3D(position=centre + size * np.array([0.75, -0.95, 0.55]),
                             look_target=centre, eye_up=(0.0, 0.0, 1.0))


def run_blueprint(views: list[rrb.Container], lock_step: bool = False) -> rrb.Blueprint:
    """The whole layout: one robot's view, or a tab per robot."""
    # the clock that means something for the run: a lock-step run's is the plant's (its wall
    # time only says how fast the host was)
    # the views take the window: the blueprint tree and the streams list are a click away
    return rrb.Blueprint(views[0] if len(views) == 1 else rrb.Tabs(*views),
                         rrb.BlueprintPanel(state="collapsed"),
                         rrb.SelectionPanel(state="collapsed"),
                         rrb.TimePanel(state="collapsed",
                                       timeline="sim_time" if lock_step else "wall_time"))


__all__ = ["JOINT_SERIES", "LOOP_SERIES", "CycleSeries", "robot_view", "run_blueprint"]
