"""The rerun layout of a run: the 3D robot, drive states, bus load and the control loop's
timing beside one time-series view per axis (position, velocity, effort tabs), so that
six axes read at a glance."""

from __future__ import annotations

import rerun.blueprint as rrb

from hil.description import RobotDescription


def run_blueprint(robot: RobotDescription, actuator_joints: dict[str, tuple[str, ...]],
                  buses: tuple[str, ...]) -> rrb.Blueprint:
    joints = [j.name for j in robot.driven_joints]
    actuators_of = {j: [a for a, js in actuator_joints.items() if j in js] for j in joints}

    def grid(name: str, contents_of) -> rrb.Grid:
        return rrb.Grid(*(rrb.TimeSeriesView(name=joint, origin="/", contents=contents_of(joint))
                          for joint in joints), name=name)

    axes = rrb.Tabs(
        grid("position", lambda j: [f"/axes/{j}/position", f"/axes/{j}/error"]),
        grid("velocity", lambda j: [f"/axes/{j}/velocity"]),
        grid("effort", lambda j: [f"/axes/{j}/effort"]
             + [f"/drives/{a}/torque" for a in actuators_of[j]]),
    )
    side = rrb.Vertical(
        rrb.Spatial3DView(name=robot.name, origin="/", contents=["/robot/**", "/joints/**"]),
        rrb.StateTimelineView(name="drive states", origin="/drives"),
        rrb.TimeSeriesView(name="bus load [%]", origin="/bus",
                           contents=[f"/bus/{b}/load" for b in buses]),
        rrb.TimeSeriesView(name="control loop [ms]: period, round trip, stalls", origin="/loop",
                           contents=["/loop/period_ms", "/loop/round_trip_ms",
                                     "/loop/stalls/**"]),
        row_shares=[3, 1, 1, 1],
    )
    return rrb.Blueprint(rrb.Horizontal(side, axes, column_shares=[2, 3]),
                         rrb.SelectionPanel(state="collapsed"))
