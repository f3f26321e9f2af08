"""The simulated bench built from its bus config: the plant, and every drive of every bus
made from its config entry."""

from __future__ import annotations

import functools
from contextlib import AbstractContextManager
from dataclasses import dataclass, replace
from pathlib import Path

import can

from hil.bus_config import BusConfig, DriveConfig, SystemConfig
from hil.bus_config.sensor_types import ImuConfig
from hil.can.router import FrameRouter
from hil.drives import DriveCore, DriveParameters, DriveProfile
from hil.description import Pose
from hil.drives.tuning import tuned_gains
from hil.plant import Plant
from hil.plant.sensor_sites import SensorKind, SensorSite
from hil.protocols import protocol
from hil.realtime.timing import Timing
from hil.sensors.can_port import CanSensorPort
from hil.sensors.force_torque import SimulatedForceTorque
from hil.sensors.imu import SimulatedImu
from hil.sensors.polled_port import PolledImuPort
from hil.sensors.serial_port import PseudoTerminal
from hil.simulator.stepping import PlantStepping

#: lock-step's shortest drive watchdog (s): a loaded machine stalls a process, which must not
#: fault a lock-step run (User-Mode Linux on a shared 2-core CI host: over 2 s seen)
LOCK_STEP_WATCHDOG = 10.0


def drive_parameters(drive: DriveConfig, motor_inertia: float) -> DriveParameters:
    """Drive parameters, with gains tuned to the motor-side inertia unless configured
    (:func:`hil.drives.tuning.tuned_gains`)."""
    gains = drive.gains
    if gains is None:
        position_kp, velocity_kp, velocity_ki = tuned_gains(
            motor_inertia, drive.velocity_bandwidth_hz, f"drive {drive.label}")
    else:
        position_kp, velocity_kp, velocity_ki = (gains.position_kp, gains.velocity_kp,
                                                 gains.velocity_ki)
    return DriveParameters(
        counts_per_rev=drive.encoder_counts_per_rev, rated_torque=drive.rated_torque,
        peak_torque=drive.peak_torque, position_kp=position_kp, velocity_kp=velocity_kp,
        velocity_ki=velocity_ki, max_velocity=drive.max_velocity,
        following_error_limit=(drive.following_error_limit
                               if protocol(drive.protocol).has_following_error else 0.0),
        following_error_timeout=drive.following_error_timeout,
        quick_stop_deceleration=drive.quick_stop_deceleration,
        watchdog_timeout=drive.watchdog_timeout, position_limits=drive.position_limits,
        holding_brake=drive.holding_brake,
        # profile moves (CiA 402 profile modes) until a master sets its own
        profile_velocity=drive.max_velocity / 4,
        profile_acceleration=drive.quick_stop_deceleration / 4,
        profile_deceleration=drive.quick_stop_deceleration / 4,
        no_load_speed=drive.effects.no_load_speed,
        velocity_filter=drive.effects.velocity_filter)


def bench_plant(config: SystemConfig) -> Plant:
    """The plant of a bus config: its robot at its plant rate, with its actuator effects, its
    scene, its base and its start pose."""
    return Plant(config.robot, timestep=1.0 / config.plant_rate_hz, effects=config.effects,
                 scene=config.scene, floating_base=config.floating_base,
                 start_pose=dict(config.start_pose),
                 sensors=tuple(SensorSite(s.name, s.link, Pose(s.xyz, s.rpy),
                                          SensorKind.IMU if isinstance(s, ImuConfig)
                                          else SensorKind.FORCE_TORQUE)
                               for s in config.sensors))


def simulated_sensors(config: SystemConfig, plant: Plant) -> list[SimulatedImu]:
    """The bus config's sensors: a serial one on a pseudo-terminal linked at its port, a CAN
    one a node waiting for its bus (:func:`attach_sensors`). Closed by :func:`close_sensors`."""
    sensors: list[SimulatedImu] = []
    try:
        for sensor in config.imus:
            sensors.append(SimulatedImu(sensor, functools.partial(plant.sensors.read,
                                                                  sensor.name),
                                        _port_of(sensor, config.path), start=plant.time))
    except BaseException:
        close_sensors(sensors)
        raise
    return sensors


def _port_of(sensor: ImuConfig, path: Path) -> PseudoTerminal | CanSensorPort | PolledImuPort:
    """Its product's wire: WitMotion's serial port, HiPNUC's CANopen node, a DM-IMU's
    answers to requests."""
    if sensor.product == "wit":
        return PseudoTerminal(sensor.port, path, sensor.line)
    if sensor.product == "hipnuc":
        return CanSensorPort(sensor.bus, sensor.node_id)
    return PolledImuPort(sensor)


def simulated_force_torques(config: SystemConfig, plant: Plant) -> list[SimulatedForceTorque]:
    """The bus config's force-torque sensors, each waiting for its bus
    (:func:`attach_sensors`)."""
    return [SimulatedForceTorque(sensor, functools.partial(plant.sensors.read, sensor.name),
                                 lambda: plant.time)
            for sensor in config.force_torques]


def attach_sensors(sensors: list[SimulatedImu], force_torques: list[SimulatedForceTorque],
                   buses: list[SimulatedBus]) -> None:
    """The CAN sensors on their buses' routers (started): a CANopen IMU boots there, a DM-IMU
    and a force-torque sensor listen for their master's requests."""
    routers = {simulated.config.name: simulated.router for simulated in buses}
    for sensor in sensors:
        port = sensor.port
        if isinstance(port, (CanSensorPort, PolledImuPort)) and sensor.config.bus in routers:
            port.attach(routers[sensor.config.bus])
    for force_torque in force_torques:
        if force_torque.config.bus in routers:
            force_torque.attach(routers[force_torque.config.bus])


def close_sensors(sensors: list[SimulatedImu],
                  force_torques: list[SimulatedForceTorque] = ()) -> None:
    """Close the sensors' ports (their links removed), take them off their buses."""
    for sensor in sensors:
        sensor.port.close()
    for force_torque in force_torques:
        force_torque.close()


@dataclass
class SimulatedBus:
    """One bus of the simulator: its config, python-can bus and drives (in config order)."""

    config: BusConfig
    bus: can.BusABC
    drives: list
    #: the drives' side of the bus (frames a bus refuses counted in its lost_frames);
    #: started by Simulator.start
    router: FrameRouter | None = None


def simulated_buses(config: SystemConfig, buses: dict[str, can.BusABC], timing: Timing,
                    lock: AbstractContextManager, stepping: PlantStepping
                    ) -> list[SimulatedBus]:
    """Every bus of ``config`` on its python-can bus, with a drive of its protocol for each
    entry (holding ``lock``), each added to the plant's ``stepping`` in the config's order."""
    inertias = stepping.plant.motor_inertias()
    actuator_index = {name: i for i, name in enumerate(stepping.plant.actuator_names)}
    simulated = []
    for bus_config in config.buses:
        drives = []
        for drive_config in bus_config.drives:
            drive = _drive(drive_config, bus_config, inertias[drive_config.actuator], timing,
                           lock)
            drives.append(drive)
            stepping.add(drive, actuator_index[drive_config.actuator])
        simulated.append(SimulatedBus(bus_config, buses[bus_config.name], drives))
    return simulated


def _drive(drive_config: DriveConfig, bus_config: BusConfig, motor_inertia: float,
           timing: Timing, lock: AbstractContextManager) -> DriveProfile:
    """The drive of a config entry: its protocol's, on its bus' cycle; in lock-step with its
    watchdog stretched to LOCK_STEP_WATCHDOG (nothing moves between commands there)."""
    parameters = drive_parameters(drive_config, motor_inertia)
    if timing.lock_step and parameters.watchdog_timeout > 0:
        parameters = replace(parameters, watchdog_timeout=max(
            parameters.watchdog_timeout, LOCK_STEP_WATCHDOG))
    core = DriveCore(parameters)
    core.set_cycle(bus_config.cycle)
    drive = protocol(drive_config.protocol).drive_class()(drive_config, core, lock)
    drive.on_bus(bus_config)
    return drive
