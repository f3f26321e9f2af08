"""The rerun layout of a run: the 3D robot, drive states, bus load and the control loop's
timing beside one time-series view per axis (position, velocity, effort tabs), so that
six axes read at a glance; several robots get a tab each."""

from __future__ import annotations

import rerun.blueprint as rrb

from hil.description import RobotDescription


def robot_view(robot: RobotDescription, actuator_joints: dict[str, tuple[str, ...]],
               buses: tuple[str, ...], root: str = "", floating_base: bool = False
               ) -> rrb.Container:
    """One robot's layout, its entities under ``root`` ("" or "/<robot>", as
    ``RunRecorder.root``); a floating base's position is plotted with the drive states."""
    joints = [j.name for j in robot.driven_joints]
    actuators_of = {j: [a for a, js in actuator_joints.items() if j in js] for j in joints}

    def grid(name: str, contents_of) -> rrb.Grid:
        return rrb.Grid(*(rrb.TimeSeriesView(name=joint, origin="/", contents=contents_of(joint))
                          for joint in joints), name=name)

    axes = rrb.Tabs(
        grid("position", lambda j: [f"{root}/axes/{j}/position", f"{root}/axes/{j}/error"]),
        grid("velocity", lambda j: [f"{root}/axes/{j}/velocity"]),
        grid("effort", lambda j: [f"{root}/axes/{j}/effort"]
             + [f"{root}/drives/{a}/{series}" for a in actuators_of[j]
                for series in ("torque", "torque_limit")]),
    )
    model = ([f"{root}/visual_geometries/**", f"{root}/collision_geometries/**"] if root
             else ["/robot/**"])
    states = rrb.StateTimelineView(name="drive states", origin=f"{root}/drives")
    if floating_base:
        states = rrb.Tabs(states, rrb.TimeSeriesView(
            name="base position [m]", origin=f"{root}/base", contents=[f"{root}/base/position"]))
    side = rrb.Vertical(
        rrb.Spatial3DView(name=robot.name, origin="/", contents=[
            *model, f"{root}/joints/**", f"{root}/scene/**", f"{root}/base"]),
        states,
        rrb.TimeSeriesView(name="bus load [%]", origin=f"{root}/bus",
                           contents=[f"{root}/bus/{b}/load" for b in buses]),
        rrb.TimeSeriesView(name="control loop [ms]: period, round trip, stalls",
                           origin=f"{root}/loop",
                           contents=[f"{root}/loop/period_ms", f"{root}/loop/round_trip_ms",
                                     f"{root}/loop/stalls/**"]),
        row_shares=[3, 1, 1, 1],
    )
    return rrb.Horizontal(side, axes, column_shares=[2, 3], name=robot.name)


def run_blueprint(views: list[rrb.Container]) -> rrb.Blueprint:
    """The whole layout: one robot's view, or a tab per robot."""
    return rrb.Blueprint(views[0] if len(views) == 1 else rrb.Tabs(*views),
                         rrb.SelectionPanel(state="collapsed"))
