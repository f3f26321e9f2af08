"""``hil check PATH``: validate a robot description or a bus config; print a summary."""

from __future__ import annotations

import argparse
import re
from dataclasses import replace
from pathlib import Path

from hil.bus_config import SystemConfig, load_bus_config
from hil.bus_config.locate import shipped_names
from hil.controllers.config import ControllersConfig, controllers_for
from hil.bus_config.types import SceneObject
from hil.cli import common
from hil.cli.describe import sensor_line
from hil.description import GeometryKind, PackagePath, RobotDescription, load_description
from hil.errors import ConfigError, Severity, UsageError
from hil.plant import Plant
from hil.simulator import bench_plant


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("path", type=Path,
                        help="robot description (.xacro, .urdf), bus config (.yaml), or the "
                             f"name of a robot with a bus config ({shipped_names()})")
    common.add_package_path(parser)
    parser.add_argument("--strict", action="store_true",
                        help="treat warnings (missing meshes, odd colours, ...) as errors")


def run(args: argparse.Namespace) -> int:
    package_path = common.package_path(args)
    if not args.path.suffix and not args.path.exists():     # a robot's name
        args.path = common.config_path(str(args.path))
    if args.path.suffix in (".yaml", ".yml"):
        config = load_bus_config(args.path, package_path)
        plant = bench_plant(config)                     # as hil sim builds it
        controllers = controllers_for(config)           # as hil control reads them
        config = replace(config, warnings=config.warnings + plant.warnings +
                         controllers.warnings)
        if args.strict and config.warnings:
            raise ConfigError([replace(w, severity=Severity.ERROR) for w in config.warnings])
        print(bus_summary(config))
        print(controllers_summary(controllers))
        return 0
    if args.path.suffix not in (".xacro", ".urdf"):
        raise UsageError.single(f"cannot check '{args.path}': not a .xacro, .urdf or .yaml file",
                                hint="give a robot description, e.g. "
                                     "robots/ur3_description/urdf/ur3.xacro, or a bus config, "
                                     "e.g. bus_config/ur3.yaml")
    description = load_description(args.path, package_path, strict=args.strict)
    print(summary(description, Plant(description), package_path))
    return 0


def controllers_summary(controllers: ControllersConfig) -> str:
    """What hil control runs: each controller, active or not, and where they come from."""
    source = controllers.path or "hil's own: no controllers file"
    return f"controllers ({source}): {controllers.summary()}"


def bus_summary(config: SystemConfig) -> str:
    """The buses and drives of a bus config, with each bus' worst-case load."""
    base = (f"base floating (root link '{config.robot.root_link}' free, standing on the scene)"
            if config.floating_base else "base fixed")
    lines = [f"bus config {config.path}: robot '{config.robot.name}' ({config.robot.source}), "
             f"plant {config.plant_rate_hz:g} Hz, control cycle {config.cycle_hz:g} Hz, {base}"]
    for bus in config.buses:
        load = bus.load()
        lines += ["", f"  bus '{bus.name}': {bus.interface} {bus.channel}, "
                      f"{bus.rates}, {len(bus.drives)} drive(s); load "
                      f"{load.worst_ratio:.0%} worst case, {load.nominal_ratio:.0%} nominal "
                      f"({load.frames_per_second:,.0f} frames/s)",
                  f"    {'node':>4}  {'joint(s)':<22}{'protocol':<9}{'counts/rev':>11}"
                  f"{'rated':>9}{'peak':>9}{'max vel':>9}{'foll.err':>9}{'watchdog':>9}  brake"]
        for d in bus.drives:
            lines.append(f"    {d.node_id:>4}  {', '.join(d.joints):<22}{d.protocol:<9}"
                         f"{d.encoder_counts_per_rev:>11} {d.rated_torque:>8.3g} "
                         f"{d.peak_torque:>8.3g} {d.max_velocity:>8.4g} "
                         f"{d.following_error_limit:>8.4g} {d.watchdog_timeout:>8.3g}  "
                         f"{'yes' if d.holding_brake else 'no'}")
    effects = config.effects
    options = {d.label: d.options for d in config.drives
               if d.options is not None and d.options.sends_velocity}
    torques = [d for d in config.drives if d.torque_feed_forward != "none"]
    if effects or options or torques:
        lines += ["", "  in force beyond the perfect motor and gear (motor side; backlash and "
                      "gear stiffness and damping at the gear's output):"]
        lines += [f"    {d.label}: " + ", ".join(f"{key} {value:g}" for key, value in
                                              d.effects.in_force().items())
                  for d in config.drives if d.actuator in effects]
        lines += [f"    {label}: feed_forward {o.feed_forward}" for label, o in options.items()]
        lines += [f"    {d.label}: torque_feed_forward {d.torque_feed_forward}" for d in torques]
    notes = [(d.label, d.options.check_notes()) for d in config.drives if d.options is not None]
    for label, lines_of_drive in notes:
        lines += [""] * bool(lines_of_drive) + [f"  {label}: {line}" for line in lines_of_drive]
    lines += ["", f"  contacts: {collision_summary(config.robot)}"
                  + (", touching the scene:" if config.scene else "; no scene to touch")]
    lines += [f"    {scene_line(thing)}" for thing in config.scene]
    if config.sensors:
        lines += ["", "  sensors:"] + [f"    {sensor.name}: {sensor_line(sensor)}"
                                       for sensor in config.sensors]
    lines.append("")
    lines.append("  units: motor side; torque N·m, velocity rad/s, following error rad, "
                 "watchdog s; effects: friction N·m and N·m·s/rad, delay s, no-load speed rad/s")
    if config.warnings:
        lines += ["", f"  {len(config.warnings)} warning(s):"] + [f"  {w}" for w in config.warnings]
    else:
        lines.append("  no warnings")
    return "\n".join(lines)


def collision_summary(description: RobotDescription) -> str:
    """How many collision shapes the robot has, on how many links, and how many stand in
    for a missing mesh."""
    shapes = [c for link in description.links for c in link.collisions]
    links = sum(1 for link in description.links if link.collisions)
    missing = sum(1 for c in shapes if c.geometry.missing_mesh)
    return (f"{len(shapes)} collision shape(s) on {links} of {len(description.links)} links"
            + (f" ({missing} the box of a link whose mesh is missing)" if missing else ""))


def scene_line(thing: SceneObject) -> str:
    """One scene object: shape, size, where, and whether it moves."""
    geometry = thing.geometry
    size = (f" {' x '.join(f'{v:g}' for v in geometry.size)} m"
            if geometry.kind is not GeometryKind.MESH else f" {geometry.mesh.name}")
    where = ", ".join(f"{v:g}" for v in thing.pose.xyz)
    moves = f"{thing.mass:g} kg, free" if thing.movable else "fixed"
    return (f"{thing.name}: {geometry.kind.value}{size if geometry.size else ''} at ({where}), "
            f"{moves}, friction {thing.friction:g}")


def summary(description: RobotDescription, plant: Plant, package_path: PackagePath) -> str:
    """A one-screen, human-readable summary of a robot and its MuJoCo model."""
    passive = description.undriven_joints
    lines = [f"robot '{description.name}'  ({description.source})",
             f"  links: {len(description.links)}  (root '{description.root_link}'),  "
             f"total mass {description.total_mass:.3f} kg",
             f"  joints: {len(description.movable_joints)} movable, "
             f"{len(description.driven_joints)} driven by actuators"
             + (f"; {len(passive)} passive (no transmission: `hil init` writes a bus config "
                "with one for each)" if passive else "")]
    lines += [f"  package '{name}': {folder}" for name, folder in
              used_packages(description, package_path).items()]
    width = max([16] + [len(j.name) + 2 for j in description.movable_joints])
    lines += ["", f"  {'joint':<{width}}{'type':<11}{'lower':>9}{'upper':>9}{'velocity':>10}"
                  f"{'effort':>9}{'damping':>9}{'friction':>9}  mimic"]
    for joint in description.movable_joints:
        limits = joint.limits
        lower = "-" if limits is None or limits.lower is None else f"{limits.lower:.4g}"
        upper = "-" if limits is None or limits.upper is None else f"{limits.upper:.4g}"
        mimic = (f"{joint.mimic.multiplier:g} x {joint.mimic.joint} + {joint.mimic.offset:g}"
                 if joint.mimic else "")
        lines.append(f"  {joint.name:<{width}}{joint.type.value:<11}{lower:>9}{upper:>9}"
                     f"{limits.velocity if limits else 0:>10.4g}"
                     f"{limits.effort if limits else 0:>9.4g}"
                     f"{joint.dynamics.damping:>9.4g}{joint.dynamics.friction:>9.4g}  {mimic}")
    names = [(s.name, a.name) for s in description.transmissions for a in s.actuators]
    t_width = max([22] + [len(t) + 2 for t, _ in names])
    a_width = max([22] + [len(a) + 2 for _, a in names])
    lines += ["", f"  {'transmission':<{t_width}}{'type':<16}{'actuator':<{a_width}}"
                  f"{'reduction':>10}{'rotor J':>10}{'max torque':>12}  joint(s)"]
    limits = dict(zip(plant.actuator_names, plant.torque_limits))
    for spec in description.transmissions:
        kind = spec.type.rsplit("/", 1)[-1].replace("Transmission", "")
        simple = len(spec.joints) == 1
        joints = ", ".join(
            j.name + ("" if simple or j.reduction == 1 else f" x{j.reduction:g}")
            + (f" offset {j.offset:g}" if j.offset else "") for j in spec.joints)
        for actuator in spec.actuators:
            reduction = actuator.reduction * (spec.joints[0].reduction if simple else 1.0)
            lines.append(f"  {spec.name:<{t_width}}{kind:<16}{actuator.name:<{a_width}}"
                         f"{reduction:>10.5g}{actuator.rotor_inertia:>10.2g}"
                         f"{limits[actuator.name]:>12.4g}  {joints}")
    model = plant.model
    lines += ["", f"  contacts: {collision_summary(description)}"]
    lines += ["", f"  MuJoCo: {model.nq} dof, {model.nu} actuators, {model.neq} mimic "
                  f"constraint(s), timestep {model.opt.timestep * 1e3:g} ms"]
    warnings = description.warnings + plant.warnings
    if warnings:
        lines += ["", f"  {len(warnings)} warning(s):"] + [f"  {w}" for w in warnings]
    else:
        lines.append("  no warnings")
    return "\n".join(lines)


def used_packages(description: RobotDescription, package_path: PackagePath) -> dict[str, Path]:
    """The packages the description's files name (``$(find pkg)``, ``package://pkg``) and
    the folder each resolved to (``not found`` shown as such)."""
    names: dict[str, None] = {}
    for file in description.files:
        try:
            text = file.read_text(errors="replace")
        except OSError:
            continue
        for match in re.finditer(r"\$\(find ([^)\s]+)\)|package://([^/\"'\s]+)", text):
            names[match.group(1) or match.group(2)] = None
    return {name: package_path.find(name) or Path("(not found on the package path)")
            for name in names}
