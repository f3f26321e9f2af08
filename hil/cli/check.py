"""``hil check PATH``: validate a robot description and print its summary."""

from __future__ import annotations

import argparse
from pathlib import Path

from hil.description import PackagePath, RobotDescription, load_description
from hil.errors import HilError
from hil.plant import Plant

HELP = "validate a robot (.xacro/.urdf) and print a summary of it"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("path", type=Path, help="robot description (.xacro or .urdf)")
    parser.add_argument("--package-path", action="append", default=[], metavar="DIR",
                        help="folder to search for $(find pkg) / package:// packages "
                             "(repeatable; before $HIL_PACKAGE_PATH and robots/)")
    parser.add_argument("--strict", action="store_true",
                        help="treat warnings (missing meshes, odd colours, ...) as errors")


def run(args: argparse.Namespace) -> int:
    if args.path.suffix not in (".xacro", ".urdf"):
        raise HilError.single(f"cannot check '{args.path}': not a .xacro or .urdf file",
                              hint="give a robot description, e.g. "
                                   "robots/ur3_description/urdf/ur3.xacro")
    package_path = PackagePath.from_environment(args.package_path)
    description = load_description(args.path, package_path, strict=args.strict)
    plant = Plant(description)
    print(summary(description, plant))
    return 0


def summary(description: RobotDescription, plant: Plant) -> str:
    """A one-screen, human-readable summary of a robot and its MuJoCo model."""
    lines = [f"robot '{description.name}'  ({description.source})",
             f"  links: {len(description.links)}  (root '{description.root_link}'),  "
             f"total mass {description.total_mass:.3f} kg",
             f"  joints: {len(description.movable_joints)} movable, "
             f"{len(description.driven_joints)} driven by actuators", ""]
    lines.append(f"  {'joint':<16}{'type':<11}{'lower':>9}{'upper':>9}{'velocity':>10}"
                 f"{'effort':>9}{'damping':>9}{'friction':>9}  mimic")
    for joint in description.movable_joints:
        limits = joint.limits
        lower = "-" if limits is None or limits.lower is None else f"{limits.lower:.4g}"
        upper = "-" if limits is None or limits.upper is None else f"{limits.upper:.4g}"
        mimic = (f"{joint.mimic.multiplier:g} x {joint.mimic.joint} + {joint.mimic.offset:g}"
                 if joint.mimic else "")
        lines.append(f"  {joint.name:<16}{joint.type.value:<11}{lower:>9}{upper:>9}"
                     f"{limits.velocity if limits else 0:>10.4g}"
                     f"{limits.effort if limits else 0:>9.4g}"
                     f"{joint.dynamics.damping:>9.4g}{joint.dynamics.friction:>9.4g}  {mimic}")
    lines += ["", f"  {'transmission':<22}{'type':<16}{'actuator':<22}{'reduction':>10}"
                  f"{'rotor J':>10}{'max torque':>12}  joint(s)"]
    limits = dict(zip(plant.actuator_names, plant.torque_limits))
    for spec in description.transmissions:
        kind = spec.type.rsplit("/", 1)[-1].replace("Transmission", "")
        simple = len(spec.joints) == 1
        joints = ", ".join(
            j.name + ("" if simple or j.reduction == 1 else f" x{j.reduction:g}")
            + (f" offset {j.offset:g}" if j.offset else "") for j in spec.joints)
        for actuator in spec.actuators:
            reduction = actuator.reduction * (spec.joints[0].reduction if simple else 1.0)
            lines.append(f"  {spec.name:<22}{kind:<16}{actuator.name:<22}{reduction:>10.5g}"
                         f"{actuator.rotor_inertia:>10.2g}{limits[actuator.name]:>12.4g}  "
                         f"{joints}")
    model = plant.model
    lines += ["", f"  MuJoCo: {model.nq} dof, {model.nu} actuators, {model.neq} mimic "
                  f"constraint(s), timestep {model.opt.timestep * 1e3:g} ms"]
    if description.warnings:
        lines += ["", f"  {len(description.warnings)} warning(s):"]
        lines += [f"  {w}" for w in description.warnings]
    else:
        lines.append("  no warnings")
    return "\n".join(lines)
