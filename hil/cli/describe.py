"""``hil describe CONFIG``: what a master needs to drive a config's simulated drives (``hil
sim CONFIG``): per bus how to join it; per drive its node id, protocol, joint, units and
every frame it and its master use, each named as the protocol names it; for CiA 402 drives
the EDS and its PDO mapping."""

from __future__ import annotations

import argparse

from hil.bus_config import BusConfig, DriveConfig, SystemConfig, load_bus_config
from hil.bus_config.locate import shipped_names
from hil.bus_config.sensor_types import ForceTorqueConfig, Sensor
from hil.can.frame import Frame, FrameSpec
from hil.cli import common
from hil.protocols import Protocol, dm_imu, hipnuc, protocol
from hil.resources import hipnuc_eds_path
from hil.zenoh_session import meeting_endpoint

def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("config", help="bus config, e.g. bus_config/ur3.yaml, or a robot's "
                                       f"name ({shipped_names()})")
    common.add_package_path(parser)


def run(args: argparse.Namespace) -> int:
    config = load_bus_config(common.config_path(args.config), common.package_path(args))
    print(f"hil describe: {config.path}: robot '{config.robot.name}', {len(config.buses)} "
          f"bus(es); positions at the motor (after the gear), SI units unless said")
    for bus in config.buses:
        _describe_bus(config, bus)
    for sensor in config.sensors:
        print(f"\nsensor '{sensor.name}': {sensor_line(sensor)}")
        if isinstance(sensor, ForceTorqueConfig):
            print("  read it: send 0x01 to its base id, take the four answers' int32 pairs "
                  "(docs/sensors.md)")
        elif sensor.product == "dm_imu":
            print(f"  read it: request each register as the maker's manual V1.1 section 3 "
                  f"has it (firmware {sensor.firmware}), decode the answers with its "
                  "uint_to_float (docs/sensors.md)")
        elif sensor.product == "wit":
            print(f"  read it: witmotion.IMU(\"{sensor.port}\", baudrate={sensor.baud}) or "
                  f"serial.Serial(\"{sensor.port}\", {sensor.baud}) (pyserial; "
                  "docs/sensors.md)")
        else:
            print(f"  read it: canopen's RemoteNode({sensor.node_id}, "
                  f"\"{hipnuc_eds_path()}\") on bus '{sensor.bus}', its TPDOs read from the "
                  "EDS (docs/sensors.md)")
    for name in dict.fromkeys(d.protocol for d in config.drives):
        lines = protocol(name).description()
        if lines:
            print()
            print("\n".join(lines))
    return 0


def sensor_line(sensor: Sensor) -> str:
    """A sensor's product, place, wire and output in words."""
    if isinstance(sensor, ForceTorqueConfig):
        return (f"{sensor.product} force-torque sensor on link '{sensor.link}', base "
                f"0x{sensor.base_id:03X} on bus '{sensor.bus}': requests at 0x"
                f"{sensor.base_id:03X} (0x01 long, 0x02 short data, 0x04 bias), answers at "
                f"0x{sensor.base_id + 1:03X}-0x{sensor.base_id + 6:03X}; "
                f"{sensor.counts_per_force:,.0f} counts/N, {sensor.counts_per_torque:,.0f} "
                "counts/N·m")
    if sensor.product == "dm_imu":
        firmware = dm_imu.FIRMWARES[sensor.firmware]
        registers = ", ".join(f"0x{kind:02X} {dm_imu.NAMES[kind]}" for kind in sensor.outputs)
        return (f"dm_imu IMU on link '{sensor.link}', CAN id {sensor.node_id} on bus "
                f"'{sensor.bus}', firmware {sensor.firmware}: requests at "
                f"0x{firmware.request_id(sensor.node_id):03X}, answers at "
                f"0x{sensor.master_id:03X}; polled at {sensor.poll_hz:g} Hz for {registers}; "
                f"samples at {sensor.rate_hz:g} Hz")
    if sensor.bus is not None:
        frames = ", ".join(f"{hipnuc.TPDO_NAMES[kind]} 0x{kind + sensor.node_id:03X}"
                           for kind in sensor.outputs)
        return (f"{sensor.product} IMU on link '{sensor.link}', CANopen node "
                f"{sensor.node_id} on bus '{sensor.bus}', {sensor.rate_hz:g} Hz of {frames}")
    packets = ", ".join(f"0x{kind:02X}" for kind in sensor.outputs)
    return (f"{sensor.product} IMU on link '{sensor.link}', serial port {sensor.port} at "
            f"{sensor.baud} baud, {sensor.rate_hz:g} Hz of packets {packets}")


def _describe_bus(config: SystemConfig, bus: BusConfig) -> None:
    print(f"\nbus '{bus.name}': {bus.interface} channel {bus.channel}, {bus.rates}, "
          f"cycle {bus.cycle_hz:g} Hz")
    fd = ", fd=True" if bus.fd else ""        # without it python-can sends and hears no FD frame
    if bus.interface == "zenoh":
        print(f"  join it: can.Bus(interface=\"zenoh\", channel=\"{bus.channel}\"{fd}) (python-can; "
              f"this host's hil processes meet at {meeting_endpoint()}; from another host add "
              "connect=[\"tcp/HOST:PORT\"], the endpoint hil sim --listen's)")
    else:
        print(f"  join it: can.Bus(interface=\"{bus.interface}\", channel=\"{bus.channel}\"{fd})"
              + (f"; candump {bus.channel}" if bus.interface == "socketcan" else ""))
    bus_wide = bus.bus_wide_frames()
    if bus_wide:
        print(f"  the master's: {', '.join(_bus_wide(spec, bus.cycle_hz) for spec in bus_wide)}")
    for drive in bus.drives:
        _describe_drive(config, bus, drive)


def _describe_drive(config: SystemConfig, bus: BusConfig, drive: DriveConfig) -> None:
    family = protocol(drive.protocol)
    reduction = config.robot.reduction(drive.actuator)
    # the reduction is per unit of the first joint (RobotDescription.reduction): a prismatic
    # joint's is a metre
    unit = config.robot.joint(drive.joints[0]).type.unit
    print(f"  node {drive.node_id}: {', '.join(drive.joints)} ({drive.protocol}); the motor "
          f"turns {reduction:.6g} rad per joint {unit}; "
          f"{drive.encoder_counts_per_rev} counts a motor turn; rated "
          f"{drive.rated_torque:.4g} N·m, peak {drive.peak_torque:.4g} N·m")
    options = {drive.node_id: drive.options}
    for frame in bus.frames(drive):
        what = _what(family, frame, options)
        when = f"{frame.rate:g}/s" if frame.rate > 0 else "on events"
        print(f"    {_identifier(frame)}  {frame.length} B  {when:>9s}  {what}{_fd_flags(frame)}")


def _fd_flags(spec: FrameSpec) -> str:
    """ " (CAN FD, BRS)" for an FD frame, nothing for a classical one."""
    if not spec.fd:
        return ""
    return " (CAN FD, BRS)" if spec.bitrate_switch else " (CAN FD)"


def _identifier(spec: FrameSpec) -> str:
    return f"0x{spec.identifier:03X}{' ext' if spec.extended else ''}"


def _bus_wide(spec: FrameSpec, cycle_hz: float) -> str:
    """A frame of the bus as a whole, as the master sends it: every cycle, at its own rate
    or on events."""
    if spec.rate == cycle_hz:
        when = f" every cycle ({spec.rate:g}/s)"
    else:
        when = f" {spec.rate:g}/s" if spec.rate > 0 else " on events"
    return f"{spec.what} {_identifier(spec)}{when}"


def _what(family: type[Protocol], frame: FrameSpec, drives: dict) -> str:
    """The frame as its protocol names it, told as a bus monitor tells it (a protocol that
    does not tell its frames' sources: as it declares it)."""
    node = next(iter(drives))
    size = frame.length
    for data in (bytes([node]) + bytes(max(0, size - 1)), bytes(size)):
        sent = Frame(frame.identifier, data, frame.extended, frame.fd, frame.bitrate_switch)
        try:
            found = family.frame_source(sent, drives)
        except NotImplementedError:
            return frame.what
        if found is not None:
            return f"{found.sender.value}: {found.what}"
    return ""
