"""A parsed bus config against its robot (every actuator driven once, joints exist) and
against the physics of its buses (node and CAN id collisions, worst-case load)."""

from __future__ import annotations

from hil.bus_config.types import LOAD_WARNING, BusConfig, DriveConfig, SystemConfig
from hil.bus_config.yaml_reader import LineMapping, Reader
from hil.can import bus_load
from hil.description.corrections import massless_free_links
from hil.errors import ConfigError
from hil.protocols import names as protocol_names
from hil.protocols import protocol
from hil.protocols.base import CanFd


def check_system(reader: Reader, config: SystemConfig, transmissions, top: LineMapping) -> None:
    """Every check of a parsed config, into ``reader``'s diagnostics."""
    names = [bus.name for bus in config.buses]
    for bus in config.buses:
        if names.count(bus.name) > 1:
            reader.fail(f"bus name '{bus.name}' is used twice", bus.line)
        seen: dict[tuple[str, int], DriveConfig] = {}     # node ids are per protocol
        for drive in bus.drives:
            key = (drive.protocol, drive.node_id)
            if drive.node_id == protocol(drive.protocol).unconfigured_node_id:
                continue            # several may wait for a master to assign theirs (LSS)
            if key in seen:
                reader.fail(f"bus '{bus.name}': node id {drive.node_id} is used by "
                            f"{seen[key].label} (line {seen[key].line}) and "
                            f"{drive.label}", drive.line, hint="give every drive on a bus its own node id")
            seen[key] = drive
        _check_ids(reader, bus)
        _check_fd(reader, bus)
        ratio = config.plant_rate_hz / bus.cycle_hz
        if abs(ratio - round(ratio)) > 1e-9 or round(ratio) < 1:
            reader.fail(f"bus '{bus.name}': cycle_hz {bus.cycle_hz:g} does not divide "
                        f"plant_rate_hz {config.plant_rate_hz:g}", bus.line,
                        hint="the plant steps a whole number of times per control cycle")
        _check_load(reader, bus)
    rates = {bus.cycle_hz for bus in config.buses}
    if len(rates) > 1:
        reader.fail(f"buses have different cycle rates ({', '.join(f'{r:g}' for r in sorted(rates))}"
                    " Hz)", top.key_lines.get("buses"),
                    hint="one controller cycle drives all buses: give them one cycle_hz")
    by_actuator: dict[str, list[DriveConfig]] = {}
    for drive in config.drives:
        by_actuator.setdefault(drive.actuator, []).append(drive)
        steps = drive.effects.delay * config.plant_rate_hz
        if abs(steps - round(steps)) > 1e-6:
            reader.warn(f"{drive.label}: effects delay {drive.effects.delay:g} s is not a whole "
                        f"number of plant steps ({1 / config.plant_rate_hz:g} s): the plant "
                        f"delays it {round(steps)} step(s)", drive.line,
                        hint="give a multiple of the plant step")
        _check_gear(reader, drive, transmissions)
        _check_carried_range(reader, drive, config.robot)
    for actuator, drives in by_actuator.items():
        if len(drives) > 1:
            reader.fail(f"actuator '{actuator}' has {len(drives)} drives "
                        f"({'; '.join(d.label for d in drives)})", drives[1].line)
    for transmission in transmissions:
        for actuator in transmission.actuators:
            if actuator not in by_actuator:
                reader.fail(f"actuator '{actuator}' (joint {', '.join(transmission.joints)}) "
                            "has no drive", top.key_lines.get("buses"),
                            hint="add a drive for it to one of the buses")
    if config.floating_base:
        for link in massless_free_links(config.robot.links, config.robot.joints):
            reader.fail(f"base: floating frees link '{link}', which has no mass (nor any link "
                        "fixed to it): MuJoCo cannot move a body without mass",
                        top.key_lines.get("base", top.line),
                        hint=f"give link '{link}' an <inertial> with the base's real mass, or "
                             "leave out 'base: floating' (a root link without <inertial> is "
                             "fixed to the world, as URDF's tools take it)")
    if config.floating_base and not any(not thing.movable for thing in config.scene):
        reader.warn("base: floating, and nothing fixed in the scene to stand on: the robot "
                    "falls for as long as the run lasts", top.key_lines.get("base", top.line),
                    hint="add a floor to 'scene:', e.g. - {name: floor, shape: plane}")


def _check_carried_range(reader: Reader, drive: DriveConfig, robot) -> None:
    """A drive whose frames map a fixed range (the MIT-style families) against what its
    joint asks of its motor: a joint that may go where the frames cannot say (a description's
    gear ahead of a motor that carries its own) cannot be sent there, nor tell it is there:
    commands and feedback saturate at the range's end, and the goal ends outside."""
    carried = drive.options.carried_range() if drive.options is not None else None
    if carried is None or len(drive.joints) != 1:
        return
    joint = robot.joint(drive.joints[0])
    reduction = abs(robot.reduction(drive.actuator))
    limits = joint.limits
    asked = []
    if limits.lower is not None and limits.upper is not None:
        reach = max(abs(limits.lower), abs(limits.upper)) * reduction
        if reach > carried.position * (1 + 1e-9):
            asked.append(f"±{reach:.4g} rad (its range), the frames carry "
                         f"±{carried.position:.4g}")
    speed = limits.velocity * reduction
    if limits.velocity > 0 and speed > carried.velocity * (1 + 1e-9):
        asked.append(f"{speed:.4g} rad/s (its velocity limit), the frames carry "
                     f"±{carried.velocity:.4g}")
    if asked:
        geared = f" (reduction {reduction:g})" if reduction != 1 else ""
        reader.warn(f"{drive.label} ({drive.protocol}): joint '{joint.name}' asks of its "
                    f"motor{geared} {'; and '.join(asked)}: beyond them its commands and feedback "
                    "saturate, and a goal there ends outside its tolerance", drive.line,
                    hint="these actuators carry their gear: mount one at the joint (reduction "
                         "1), or give p_max/v_max in the drive's options where its firmware "
                         "maps wider")


def _check_gear(reader: Reader, drive: DriveConfig, transmissions) -> None:
    """Backlash and gear compliance need the one joint of a simple transmission, and one of
    the two: a dead band with a spring beyond it is not modelled."""
    effects = drive.effects
    if not effects.gear_stage:
        return
    transmission = next((t for t in transmissions if drive.actuator in t.actuators), None)
    if transmission is not None and len(transmission.joints) > 1:
        reader.fail(f"{drive.label}: backlash and gear stiffness act between one motor and "
                    f"one joint, not on a coupled transmission ({', '.join(transmission.joints)})",
                    drive.line, hint="leave them out of this drive's effects")
    if effects.backlash and (effects.gear_stiffness or effects.gear_damping):
        reader.fail(f"{drive.label}: effects backlash and gear_stiffness/gear_damping together "
                    "(a dead band with a spring beyond it) are not modelled", drive.line,
                    hint="give one: backlash for a stiff gear with play, gear_stiffness and "
                         "gear_damping for a compliant one without")
    if effects.gear_damping and not effects.gear_stiffness:
        reader.fail(f"{drive.label}: effects gear_damping without gear_stiffness: a damper "
                    "alone would let the link drift from its motor", drive.line,
                    hint="give the gear's stiffness too")


_DRIVE_CLASH = ("change a node id (or a protocol option such as reply_id), or put the drives "
                "on separate buses")
_SENSOR_CLASH = ("change the sensor's ids in its entry (node_id, master_id or base_id) or the "
                 "drive's node id, or put the sensor on another bus")


def _check_ids(reader: Reader, bus: BusConfig) -> None:
    """Two drives (of any protocols) must not use the same CAN id on one bus, nor a drive
    an id of the bus as a whole (CANopen's NMT and SYNC) or of a sensor on it."""
    # an 11-bit and a 29-bit identifier of one number are two frames (ISO 11898-1's IDE bit)
    owners: dict[tuple[int, bool], str] = {
        (spec.identifier, spec.extended): f"the master's {spec.what} ({family.name})"
        for family in bus.protocols for spec in family.bus_wide_frames(bus.cycle_hz)}
    for sensor_frame in bus.sensor_frames:
        key = (sensor_frame.identifier, sensor_frame.extended)
        held = owners.get(key)
        # masters' requests to two sensors may share an id (the DM-IMU manual's 0x6FF
        # carries the CAN id it asks); any other frame is one device's
        if held is not None and not (held.endswith("request")
                                     and sensor_frame.what.endswith("request")):
            reader.fail(f"bus '{bus.name}': CAN id 0x{key[0]:03X} is used by {held} and by "
                        f"{sensor_frame.what}", bus.line, hint=_SENSOR_CLASH)
        owners.setdefault(key, sensor_frame.what)
    sensor_ids = {(spec.identifier, spec.extended) for spec in bus.sensor_frames}
    shared: dict[tuple[int, bool], str] = {}
    for drive in bus.drives:
        spec = protocol(drive.protocol)
        label = f"{drive.label} ({drive.protocol})"
        sharable = spec.shared_ids(drive.options)
        for key in sorted({(frame.identifier, frame.extended) for frame in bus.frames(drive)}):
            can_id, extended = key
            if can_id in sharable and shared.get(key) == drive.protocol:
                continue
            if key in owners:
                reader.fail(f"bus '{bus.name}': CAN id 0x{can_id:03X}{' ext' if extended else ''}"
                            f" is used by {owners[key]} and by {label}", drive.line,
                            hint=_SENSOR_CLASH if key in sensor_ids else _DRIVE_CLASH)
                continue
            owners[key] = label
            if can_id in sharable:
                shared[key] = drive.protocol


def _check_fd(reader: Reader, bus: BusConfig) -> None:
    """An FD-only device needs an FD bus; a classical-only one cannot share a bus with FD
    frames (it destroys them with error frames: :class:`hil.protocols.base.CanFd`)."""
    if any(d.protocol not in protocol_names() for d in bus.drives):
        return
    families = {drive.protocol: protocol(drive.protocol).can_fd for drive in bus.drives}
    for drive in bus.drives:
        if families[drive.protocol] is CanFd.FD_ONLY and not bus.fd:
            reader.fail(f"bus '{bus.name}': {drive.label} speaks CAN FD only ({drive.protocol}), "
                        "on a classical bus", drive.line or bus.line,
                        hint="add fd: true (and data_bitrate) to the bus")
    fd_families = sorted(name for name, kind in families.items() if kind is not CanFd.CLASSIC)
    if not bus.fd or not fd_families:
        return
    for drive in bus.drives:
        if families[drive.protocol] is CanFd.CLASSIC:
            reader.fail(f"bus '{bus.name}': {drive.label} is a classical CAN device "
                        f"({drive.protocol}) on an FD bus whose {', '.join(fd_families)} "
                        "drives exchange FD frames: its controller would answer each with an "
                        "error frame", drive.line or bus.line,
                        hint="put the classical drives on a bus of their own (no fd: true)")


def _check_load(reader: Reader, bus: BusConfig) -> None:
    if not bus.drives or any(d.protocol not in protocol_names() for d in bus.drives):
        return
    load = bus.load()
    summary = (f"bus '{bus.name}': {len(bus.drives)} drive(s) at {bus.cycle_hz:g} Hz need "
               f"{load.worst_bits_per_second / 1e3:,.0f} kbit/s worst case "
               f"({load.nominal_bits_per_second / 1e3:,.0f} nominal, "
               f"{load.frames_per_second:,.0f} frames/s) on a {bus.rates} bus: "
               f"{load.worst_ratio:.0%}")
    if load.worst_ratio <= LOAD_WARNING:
        return
    # the bus-wide frames (a SYNC) stay however the drives are split
    shared_bits = bus_load(bus.bitrate, [spec for spec in bus.bus_wide_frames()
                                         if spec.rate > 0],
                           bus.data_bitrate).worst_bits_per_second
    per_drive = (load.worst_bits_per_second - shared_bits) / len(bus.drives)
    budget = LOAD_WARNING * bus.bitrate
    fitting_rate = budget / (load.worst_bits_per_second / bus.cycle_hz)   # the load is > 0 here
    split = (f"split the drives over buses of at most "
             f"{max(int((budget - shared_bits) // per_drive), 1)} drive(s) each, or "
             if per_drive > 0 else "")     # bus-wide frames alone over the line: no split helps
    hint = (f"{split}lower cycle_hz to {fitting_rate:,.0f} Hz or less (either keeps the load "
            f"under {LOAD_WARNING:.0%})")
    if load.worst_ratio > 1.0:
        reader.fail(f"{summary}: infeasible", bus.line, hint=hint)
    else:
        reader.warn(f"{summary}: above {LOAD_WARNING:.0%}, no room for SDO, EMCY and retries",
                    bus.line, hint=hint)


def check_together(configs: list[SystemConfig]) -> None:
    """ConfigError unless benches can share one Zenoh network and one recording: every robot
    named once (its keys are ``hil/<robot>/...``), every CAN channel used by one bus only
    (two benches' drives on one bus would answer each other's master)."""
    robots: dict[str, SystemConfig] = {}
    channels: dict[str, tuple[SystemConfig, BusConfig]] = {}
    for config in configs:
        other = robots.setdefault(config.robot.name, config)
        if other is not config:
            raise ConfigError.single(
                f"robot '{config.robot.name}' is named by two configs ({other.path} and "
                f"{config.path}): its processes and keys would be one robot's", config.path,
                hint="give each robot once (two of one robot need URDFs of different names)")
        for bus in config.buses:
            first = channels.setdefault(bus.channel, (config, bus))
            if first[1] is not bus:
                raise ConfigError.single(
                    f"bus '{bus.name}' of robot '{config.robot.name}' is on channel "
                    f"'{bus.channel}', which bus '{first[1].name}' of robot "
                    f"'{first[0].robot.name}' ({first[0].path}) uses too", config.path, bus.line,
                    hint="give each bus a channel of its own")
