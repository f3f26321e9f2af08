"""Each drive ``hil init`` writes, with what its protocol needs to hold its joint: the
options it writes (``Protocol.initial_options``), and where the drive holds position with
the master's PD alone, the feed-forward and stiffness that keep it where it is sent.

MIT-family motors (mit, damiao, cubemars) run the master's PD and nothing else: the MIT
Cheetah motor firmware's torque is ``kp (p_des - p) + kd (v_des - v) + t_ff`` (Ben Katz,
motorcontrol ``foc.c``), no integral. A gravity load L sags such a joint L / kp: a UR5 on
Damiao drives, kp 500 N·m/rad at most (the command's range), hung 0.21 rad below its
goal. So the master sends gravity as ``t_ff`` (``torque_feed_forward: gravity``, from the
description) on every such drive whose joint carries a gravity load, except the joints a
standing robot stands on: the master's model hangs the robot from its root, and those
joints carry it from its feet. Those get the stiffness that holds their standing load
within STANCE_SAG; where the command's kp range cannot, ``hil init`` says so.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, replace

from hil.bus_config.types import Gains
from hil.commissioning.sizing import MotorClass, Sizing, fitting
from hil.controllers.config import DEFAULT_GOAL_TOLERANCE
from hil.description import RobotDescription
from hil.plant import Plant
from hil.protocols.base import DriveSetting

#: MIT motors hold position with the master's kp/kd: a critically damped loop at this
#: bandwidth on the joint's inertia at the zero pose, reflected to the motor
MIT_BANDWIDTH_HZ = 10.0
#: the velocity loops of the joints a standing robot stands on (Hz): under the ground's own
#: contact (a 4 ms time constant, hil.plant's CONTACT_SOLREF): at the default 40 Hz a Go1's
#: calves chattered between their peak torques and it shuffled across the floor; at 20 Hz
#: (and 10) it stood still, 0.1 of its peak torque, no drift (lock-step, measured)
STANCE_BANDWIDTH_HZ = 20.0
#: how far (rad, m) a PD-only joint a robot stands on may sag under its standing load: a
#: quarter of the demo's goal tolerance, the rest left to the sway about it (hil's choice:
#: a G1 on Damiao drives, kp 500 on its legs and kd at most 5, swayed +-0.008 rad about
#: 0.011 at its ankles, lock-step, measured; at the 10 Hz kp, 226, it sagged 0.07 and fell)
STANCE_SAG = DEFAULT_GOAL_TOLERANCE / 4
#: the stiffest a PD-only stance joint is made (Hz, on the least inertia its motor sees):
#: well inside the plant's 1 kHz step (hil's choice)
STANCE_MOST_HZ = 50.0


@dataclass(frozen=True)
class Drive:
    """One drive to write: its joint, actuator, what the config adds for it (if anything)."""

    joint: str
    actuator: str
    sizing: Sizing | None          # None: the description's own transmission
    rated_torque: float | None
    options: dict | None = None
    velocity_bandwidth_hz: float | None = None     # None: the bus config's default
    gravity_feed_forward: bool = False
    gains: Gains | None = None                      # None: hil sim tunes the drive's loops


def with_options(robot: RobotDescription, drives: list[Drive], spec,
                 catalogue: tuple[MotorClass, ...], holding: Mapping[str, float],
                 standing: Mapping[str, float]) -> tuple[list[Drive], list[str]]:
    """Each drive with the options its protocol writes (``Protocol.initial_options``): from
    the motor side of its joint, the master's gains (see MIT_BANDWIDTH_HZ) and, where the
    protocol knows its products, the model sized for it; where those options give the
    master's PD (a ``kp``), gravity feed-forward for a joint that ``holding`` says carries
    a load, or for a joint the robot stands on (``standing``: its load) the stiffness that
    holds it (the module's doc). And what to tell the user: stance joints the command's kp
    range leaves sagging more than half the demo's goal tolerance."""
    inertias = Plant(robot).motor_inertias()       # at the start pose
    omega = 2 * math.pi * MIT_BANDWIDTH_HZ
    result, notes = [], []
    for drive in drives:
        names = [name.strip() for name in drive.joint.split(",")]
        joint = robot.joint(names[0])
        reduction = abs(robot.reduction(drive.actuator))
        inertia = inertias[drive.actuator]
        limits = joint.limits
        reach = (max(abs(limits.lower), abs(limits.upper)) if limits.lower is not None
                 else 2 * math.pi)                           # unlimited: two turns each way
        peak, speed = limits.effort / reduction, limits.velocity * reduction
        model = None
        if spec.models:
            model = (drive.sizing.motor if drive.sizing is not None
                     else fitting(catalogue, peak, speed)).name
        kp = inertia * omega ** 2
        stance_load = max((standing[n] for n in names if n in standing), default=None)
        if stance_load is not None:        # motor side: load / reduction, sag x reduction
            kp = max(kp, min(stance_load / reduction / (STANCE_SAG * reduction),
                             inertia * (2 * math.pi * STANCE_MOST_HZ) ** 2))
        options = spec.initial_options(DriveSetting(reach * reduction, speed, peak, kp,
                                                    2 * inertia * omega, model))
        pd_only = bool(options) and "kp" in options and spec.carries_torque_feed_forward
        feed_forward = (pd_only and stance_load is None
                        and any(holding.get(n, 0.0) > 0.0 for n in names))
        if pd_only and stance_load is not None:
            sag = stance_load / (options["kp"] * reduction ** 2)
            if sag > DEFAULT_GOAL_TOLERANCE / 2:
                notes.append(f"joint '{drive.joint}' holds {stance_load:.3g} "
                             f"{joint.type.effort_unit} standing: at kp {options['kp']:g}, "
                             f"the stiffest its {spec.name} command's range (or its motor's "
                             f"inertia, STANCE_MOST_HZ) allows, it sags {sag:.3g} "
                             f"{joint.type.unit}, more than half the demo's goal tolerance "
                             f"({DEFAULT_GOAL_TOLERANCE:g}); the demo may end outside it: a "
                             "motor with a higher reduction, or a controller that balances")
        result.append(replace(drive, options=options, gravity_feed_forward=feed_forward))
    return result, notes
