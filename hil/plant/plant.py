"""The MuJoCo plant: the robot's physics, seen from the motors.

Drives call :meth:`Plant.motor_positions` / :meth:`Plant.motor_velocities`
(motor side, through the transmissions), :meth:`Plant.set_motor_torques`
and :meth:`Plant.step`; everything else reads joint states.
"""

from __future__ import annotations

import ctypes
import functools
import time
from collections.abc import Mapping

import mujoco
import numpy as np

from hil.description import GeometryKind, RobotDescription
from hil.errors import Diagnostic, warning
from hil.plant.builder import (
    DEFAULT_TIMESTEP, FLOATING_BASE, GEAR_STAGE, ActuatorLosses, build_spec, compile_model,
)
from hil.plant.sensor_sites import SensorReadings, SensorSite, add_sensor_sites
from hil.plant.inertia import motor_inertias
from hil.plant.shapes import (MUJOCO_MESHES, ROBOT_CONTACT, ScenePart, scene_name,
                              unreadable_mesh)
from hil.transmissions import Transmission, TransmissionStack, build_transmissions

#: a shape rests on the ground when its bottom is this close to the robot's lowest point (m)
RESTING = 0.005


class Plant:
    """A MuJoCo model of one robot with one motor per transmission actuator.

    Actuator arrays are ordered as :attr:`actuator_names`; joint arrays as
    :attr:`joint_names` (every movable joint, mimic joints included, in URDF
    order). Units are SI on both sides: rad or m for joints, rad for motors,
    N·m or N for efforts.
    """

    def __init__(self, description: RobotDescription, timestep: float = DEFAULT_TIMESTEP,
                 effects: Mapping[str, ActuatorLosses] | None = None,
                 scene: tuple[ScenePart, ...] = (), floating_base: bool = False,
                 start_pose: Mapping[str, float] | None = None,
                 sensors: tuple[SensorSite, ...] = ()):
        """``effects``: the motor losses of actuators that have any, by actuator name;
        ``scene``: the things in the robot's world; ``floating_base``: the robot's root
        moves freely and starts standing on the scene (:meth:`base_pose`); ``start_pose``:
        where joints start, over :func:`initial_pose`; ``sensors``: the sensors on its links,
        read by :attr:`sensors`."""
        _avoid_slow_clock()
        self.description = description
        self.scene = scene
        self.transmissions: tuple[Transmission, ...] = build_transmissions(description)
        self.spec, self.bindings = build_spec(description, self.transmissions, timestep,
                                              effects, scene, floating_base)
        add_sensor_sites(self.spec, sensors)
        self.model = compile_model(self.spec, description)
        self.data = mujoco.MjData(self.model)
        self.sensors = SensorReadings(self.model, self.data, sensors)
        mujoco.mj_forward(self.model, self.data)
        # views of the data's arrays, made once: reading data.qpos makes a new array each
        # time (a pybind11 property), and the simulator reads these at every plant step
        self._qpos_view, self._qvel_view = self.data.qpos, self.data.qvel
        self._ctrl_view = self.data.ctrl

        self.joint_names = tuple(j.name for j in description.movable_joints)
        self.actuator_names = tuple(b.name for b in self.bindings)
        self._qpos = np.array([self.model.joint(n).qposadr[0] for n in self.joint_names])
        self._dof = np.array([self.model.joint(n).dofadr[0] for n in self.joint_names])
        # joints with a gear stage (backlash, compliance): the link is at the sum of both
        stages = [(k, mujoco.mj_name2id(self.model, mujoco.mjtObj.mjOBJ_JOINT,
                                        GEAR_STAGE.format(joint=name)))
                  for k, name in enumerate(self.joint_names)]
        stages = [(k, stage) for k, stage in stages if stage >= 0]
        self._staged = np.array([k for k, _ in stages], dtype=int)
        self._stage_qpos = np.array([self.model.jnt_qposadr[j] for _, j in stages], dtype=int)
        self._stage_dof = np.array([self.model.jnt_dofadr[j] for _, j in stages], dtype=int)
        driven = [j for t in self.transmissions for j in t.joints]
        driven_qpos = np.array([self.model.joint(n).qposadr[0] for n in driven], dtype=int)
        driven_dof = np.array([self.model.joint(n).dofadr[0] for n in driven], dtype=int)
        motors = TransmissionStack(self.transmissions, tuple(driven), self.actuator_names)
        # the transmissions over the whole of qpos and qvel: a = P q - P offset as one
        # product per read, no gather (the simulator reads both at every plant step)
        self._position_map = np.zeros((len(self.actuator_names), self.model.nq))
        self._position_map[:, driven_qpos] = motors.position_matrix
        self._position_bias = motors.position_matrix @ motors.joint_offsets
        # most robots have none: then x - 0 is x, and motor_positions skips a numpy call
        self._has_position_bias = bool(np.count_nonzero(self._position_bias))
        self._velocity_map = np.zeros((len(self.actuator_names), self.model.nv))
        self._velocity_map[:, driven_dof] = motors.position_matrix
        self._actuator_ids = np.array([self.model.actuator(n).id for n in self.actuator_names])
        # the builder adds exactly the bindings' actuators, in their order: ctrl is theirs,
        # set whole by a slice at every step (not a gather)
        if list(self._actuator_ids) != list(range(self.model.nu)):
            raise RuntimeError(f"the model's actuators {self._actuator_ids.tolist()} are not "
                               "the bindings' in order (a defect of hil.plant.builder)")
        base = mujoco.mj_name2id(self.model, mujoco.mjtObj.mjOBJ_JOINT, FLOATING_BASE)
        self._base = int(self.model.jnt_qposadr[base]) if base >= 0 else None
        self.set_joint_positions({**initial_pose(description), **(start_pose or {})})
        if self._base is not None:
            self._stand_on_the_ground()

    def motor_inertias(self) -> dict[str, float]:
        """Each actuator's inertia seen from its motor shaft (rotor + reflected load) in the
        present pose, the least it can see: with every other joint free to move. For a
        transmission a = P q that is 1 / (P M^-1 P^T)_kk.

        A drive tuned on it stays stable however its neighbours move. The inertia with the
        other joints held (M_kk) is up to 5x larger for a shoulder and elbow driven by small
        motors through large ratios (measured on a mobile manipulator's arm sized by `hil
        init`): velocity loops tuned on that ran at up to 5x their bandwidth when the other
        axis gave way, and a braked elbow beside an enabled shoulder oscillated at about
        350 Hz, never at standstill.

        A floating robot standing moves under what it rests on the ground on: its feet stay
        where they are, its wheels roll, a caster slides
        (:func:`hil.plant.inertia.ground_constraints`). math.inf for a motor that the ground
        holds still: no drive can be tuned on it (:func:`hil.drives.tuning.tuned_gains`
        refuses it)."""
        return motor_inertias(self)

    @property
    def warnings(self) -> tuple[Diagnostic, ...]:
        """STL/OBJ meshes MuJoCo could not read, which the plant draws as their link's box
        (each with MuJoCo's reason). DAE meshes are boxes in the plant without a word: MuJoCo
        has no reader for them, and the recording draws them."""
        return tuple(
            warning(f"link '{link.name}' mesh '{visual.geometry.mesh}': the plant draws the "
                    f"link's box instead ({reason}); the recording draws the mesh",
                    self.description.source,
                    hint="convert the mesh to binary STL or OBJ to see it in MuJoCo too")
            for link in self.description.links for visual in link.visuals
            if visual.geometry.mesh is not None
            and (reason := unreadable_mesh(visual.geometry.mesh)) is not None
            and visual.geometry.mesh.suffix.lower() in MUJOCO_MESHES)

    # --- motor side --------------------------------------------------------

    @property
    def torque_limits(self) -> np.ndarray:
        return np.array([b.torque_limit for b in self.bindings])

    # ndarray.dot, not @ (read at every plant step; see hil.transmissions.base)
    def motor_positions(self) -> np.ndarray:
        positions = self._position_map.dot(self._qpos_view)
        return positions - self._position_bias if self._has_position_bias else positions

    def motor_velocities(self) -> np.ndarray:
        return self._velocity_map.dot(self._qvel_view)

    def set_motor_torques(self, torques) -> None:
        """Command motor torques; MuJoCo saturates them at :attr:`torque_limits`."""
        self._ctrl_view[:] = torques

    def motor_torques(self) -> np.ndarray:
        """Torques the motors actually apply (after saturation)."""
        return self.data.actuator_force[self._actuator_ids].copy()

    # --- time --------------------------------------------------------------

    @functools.cached_property    # read every step; the model's timestep is fixed once built
    def timestep(self) -> float:
        return float(self.model.opt.timestep)

    @property
    def time(self) -> float:
        return float(self.data.time)

    def step(self, steps: int = 1) -> None:
        mujoco.mj_step(self.model, self.data, nstep=steps)

    # --- joint side ---------------------------------------------------------

    def joint_positions(self) -> np.ndarray:
        """Where the links are: a joint with a gear stage at the sum of its two hinges."""
        positions = self.data.qpos[self._qpos]
        positions[self._staged] += self.data.qpos[self._stage_qpos]
        return positions

    def joint_velocities(self) -> np.ndarray:
        velocities = self.data.qvel[self._dof]
        velocities[self._staged] += self.data.qvel[self._stage_dof]
        return velocities

    def joint_efforts(self) -> np.ndarray:
        """Actuator efforts at the joints (motor torques through the transmissions)."""
        return self.data.qfrc_actuator[self._dof].copy()

    def set_joint_positions(self, positions: Mapping[str, float],
                            velocities: Mapping[str, float] | None = None) -> None:
        """Place joints (e.g. an initial pose), at rest or moving at ``velocities``, mimic
        joints following, a gear stage in the middle of its play."""
        stages = dict(zip(self._staged, self._stage_qpos))
        for name, value in positions.items():
            self.data.qpos[self.model.joint(name).qposadr[0]] = value
            stage = stages.get(self.joint_names.index(name)) if name in self.joint_names else None
            if stage is not None:
                self.data.qpos[stage] = 0.0
        for joint in self.description.joints:
            if joint.mimic is not None:
                leader = self.data.qpos[self.model.joint(joint.mimic.joint).qposadr[0]]
                self.data.qpos[self.model.joint(joint.name).qposadr[0]] = (
                    joint.mimic.multiplier * leader + joint.mimic.offset)
        self.data.qvel[:] = 0.0
        for name, value in (velocities or {}).items():
            self.data.qvel[self.model.joint(name).dofadr[0]] = value
        mujoco.mj_forward(self.model, self.data)

    # --- a floating base ------------------------------------------------------

    @property
    def floating(self) -> bool:
        """Whether the robot's root moves freely (``base: floating``)."""
        return self._base is not None

    def base_pose(self) -> tuple[np.ndarray, np.ndarray]:
        """Where a floating base is: its position (m) and orientation (quaternion w, x, y, z)
        in the world; the world's origin for a fixed one."""
        if self._base is None:
            return np.zeros(3), np.array([1.0, 0.0, 0.0, 0.0])
        qpos = self.data.qpos[self._base:self._base + 7]
        return qpos[:3].copy(), qpos[3:].copy()

    def _stand_on_the_ground(self) -> None:
        """Lower (or raise) the floating base until the robot's lowest point touches the
        ground: the highest fixed plane of the scene, or z = 0."""
        ground = max((part.pose.xyz[2] for part in self.scene
                      if part.mass == 0 and part.geometry.kind is GeometryKind.PLANE),
                     default=0.0)
        self.data.qpos[self._base + 2] += ground - self.lowest_point()
        mujoco.mj_forward(self.model, self.data)

    @property
    def base_body(self) -> int | None:
        """The MuJoCo body id of a floating base (None: fixed)."""
        if self._base is None:
            return None
        return int(self.model.jnt_bodyid[self.model.joint(FLOATING_BASE).id])

    def resting_points(self, tolerance: float = RESTING) -> dict[int, list[np.ndarray]]:
        """The robot's bodies whose shapes rest on the ground now (their bottom within
        ``tolerance`` of the robot's lowest point), each with the corners of those bottoms
        (world frame; MuJoCo body ids): its feet, or its wheels, or a base plate."""
        model, data = self.model, self.data
        lowest = self.lowest_point()
        box = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)])
        resting: dict[int, list[np.ndarray]] = {}
        for geom in self.ground_shapes:
            turn = data.geom_xmat[geom].reshape(3, 3)
            centre, half = model.geom_aabb[geom][:3], model.geom_aabb[geom][3:]
            corners = data.geom_xpos[geom] + (centre + box * half) @ turn.T
            bottom = corners[corners[:, 2] <= lowest + tolerance]
            if len(bottom):
                resting.setdefault(int(model.geom_bodyid[geom]), []).extend(bottom)
        return resting

    def lowest_point(self) -> float:
        """The height of the robot's lowest point now (m), of its :attr:`ground_shapes`
        (each shape's box in its own frame, turned)."""
        model, data = self.model, self.data
        lowest = np.inf
        for geom in self.ground_shapes:
            turn = data.geom_xmat[geom].reshape(3, 3)
            centre, half = model.geom_aabb[geom][:3], model.geom_aabb[geom][3:]
            lowest = min(lowest, data.geom_xpos[geom][2] + turn[2] @ centre
                         - np.abs(turn[2]) @ half)
        return float(lowest)

    @functools.cached_property
    def ground_shapes(self) -> np.ndarray:
        """The robot's shapes that may touch the ground (MuJoCo geom ids): its collision
        shapes, or all its shapes where it has none."""
        model = self.model
        scene = [model.body(scene_name(part.name)).id for part in self.scene]
        robot = (model.geom_bodyid >= 1) & np.isin(model.geom_bodyid, scene, invert=True)
        colliding = robot & (model.geom_contype & ROBOT_CONTACT).astype(bool)
        return np.flatnonzero(colliding if colliding.any() else robot)

    # --- the scene -----------------------------------------------------------

    def moving_objects(self) -> tuple[str, ...]:
        """The scene objects that move (those with a mass), in the scene's order."""
        return tuple(part.name for part in self.scene if part.mass > 0)

    def contacts(self) -> tuple[np.ndarray, np.ndarray]:
        """Where things touch now, and how hard: each contact's point (m) and the force on
        its first body (N), both in the world frame, (contacts, 3) each."""
        data = self.data
        count = data.ncon
        points, forces = np.empty((count, 3)), np.empty((count, 3))
        wrench = np.empty(6)
        for index in range(count):
            contact = data.contact[index]
            mujoco.mj_contactForce(self.model, data, index, wrench)
            points[index] = contact.pos
            # the force is in the contact's frame (rows: normal, two tangents); the normal
            # points from the first geom to the second, so the first body feels its opposite
            forces[index] = -contact.frame.reshape(3, 3).T @ wrench[:3]
        return points, forces

    def object_pose(self, name: str) -> tuple[np.ndarray, np.ndarray]:
        """Where a scene object is: its position (m) and orientation (quaternion w, x, y, z)
        in the world."""
        body = self.data.body(scene_name(name))
        return body.xpos.copy(), body.xquat.copy()

    def inverse_dynamics(self) -> np.ndarray:
        """Joint forces MuJoCo needs for the current state and acceleration."""
        mujoco.mj_inverse(self.model, self.data)
        return self.data.qfrc_inverse[self._dof].copy()


_clock_checked = False


def _avoid_slow_clock() -> None:
    """Keep MuJoCo's profiling timers off the clock where reading it is a syscall.

    MuJoCo reads its timer about 30 times per step for the statistics in
    ``mjData.timer``, which hil does not use. Where the clock has no vDSO
    (User-Mode Linux, some sandboxes) each read is a system call and a step
    becomes orders of magnitude slower (docs/performance.md, "2026-12-06, later: figures
    from code comments"). There, MuJoCo gets libc's ``drand48`` as its time
    source: native, no system call (a Python callable would cost more than
    the step); its timer statistics are then meaningless.
    """
    global _clock_checked
    if _clock_checked:
        return
    _clock_checked = True
    start = time.perf_counter()
    for _ in range(200):
        time.perf_counter()
    if (time.perf_counter() - start) / 200 < 2e-6:    # a vDSO clock reads well under this
        return
    source = ctypes.CDLL(None).drand48
    source.restype, source.argtypes = ctypes.c_double, []
    mujoco.set_mjcb_time(source)


#: how far inside its range a joint starts whose range excludes zero (share of the range)
INITIAL_MARGIN = 0.1


def initial_pose(description: RobotDescription) -> dict[str, float]:
    """Where the robot starts: every joint at zero, or INITIAL_MARGIN of its range inside
    the nearer end where zero lies outside it or on an end (a real robot is powered up
    inside its limits, and a drive faults on a position limit it starts on)."""
    pose = {}
    for joint in description.movable_joints:
        limits = joint.limits
        if joint.mimic is None and limits is not None and limits.lower is not None:
            margin = INITIAL_MARGIN * (limits.upper - limits.lower)
            if not limits.lower < 0.0 < limits.upper:
                pose[joint.name] = (limits.lower + margin if limits.lower >= 0.0
                                    else limits.upper - margin)
    return pose
