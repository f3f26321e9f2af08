"""A bus config as typed objects: the bench (robot, plant rate, buses), each bus and each
drive. Drive quantities are motor side, SI units (rad, rad/s, N·m)."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

from hil.bus_config.sensor_types import ForceTorqueConfig, ImuConfig, Sensor
from hil.can import BusLoad, bus_load
from hil.can.frames import BitRates
from hil.can.frame import Frame, FrameSpec
from hil.description import Geometry, Pose, RobotDescription
from hil.errors import Diagnostic
from hil.protocols import protocol
from hil.protocols.base import Protocol, ProtocolOptions

#: Bus load above which a bus has no room left for SDO, EMCY, heartbeats and retries.
LOAD_WARNING = 0.8


@dataclass(frozen=True)
class Gains:
    position_kp: float      # 1/s
    velocity_kp: float      # N·m·s/rad
    velocity_ki: float      # N·m/rad


@dataclass(frozen=True)
class ActuatorEffects:
    """What a real motor and gear add to a perfect one, motor side, each off (0) unless a bus
    config sets it (``effects:``; the equations are the README's "Actuator effects"). They act
    in the plant or the drive, so every protocol and every master meets them."""

    #: N·m: Coulomb friction, -c·sign(ω) while moving; at rest it holds up to c (breakaway):
    #: MuJoCo's frictionloss, on the joint (c x reduction) or the coupled motor's tendon
    coulomb_friction: float = 0.0
    #: N·m·s/rad: viscous friction, -b·ω: MuJoCo's actuator damping
    viscous_friction: float = 0.0
    #: s: the motor applies the torque the drive commanded this long before (a transport or
    #: current-loop delay): MuJoCo's actuator delay, zero-order hold, whole plant steps
    delay: float = 0.0
    #: rad/s: the torque-speed line of a motor at its supply voltage: driving, |τ| is at most
    #: τ_peak (1 - |ω|/ω0), braking the full τ_peak; 0: no line (hil's drive applies it)
    no_load_speed: float = 0.0
    #: rad (m) at the gear's output: its backlash, a dead band the output moves through
    #: freely whenever the motor reverses: a second MuJoCo hinge on the joint's axis,
    #: limited to ±width/2 with hard ends (simple transmissions)
    backlash: float = 0.0
    #: N·m/rad (N/m) and N·m·s/rad (N·s/m) at the gear's output: its torsional stiffness and
    #: damping, a spring and damper between motor side and link: the same second hinge with
    #: MuJoCo's joint stiffness and damping (simple transmissions; not with backlash)
    gear_stiffness: float = 0.0
    gear_damping: float = 0.0
    #: s: the drive measures velocity from its encoder (the count difference over each
    #: plant step, as a drive without a tachometer does) through a first-order low-pass of
    #: this time constant; 0: the plant's exact velocity
    velocity_filter: float = 0.0

    KEYS = ("coulomb_friction", "viscous_friction", "delay", "no_load_speed", "backlash",
            "gear_stiffness", "gear_damping", "velocity_filter")
    #: the effects that put a stage between the motor and the link (a second hinge)
    GEAR_KEYS = ("backlash", "gear_stiffness", "gear_damping")

    def in_force(self) -> dict[str, float]:
        """The effects set (not 0), by key."""
        return {key: getattr(self, key) for key in self.KEYS if getattr(self, key)}

    @property
    def gear_stage(self) -> bool:
        """Whether the gear is more than a perfect ratio (backlash or compliance)."""
        return any(getattr(self, key) for key in self.GEAR_KEYS)


NO_EFFECTS = ActuatorEffects()


@dataclass(frozen=True)
class SceneObject:
    """A thing in the robot's world (the bus config's ``scene:``): a ground plane, a table, a
    box to grasp. With a mass it moves freely (MuJoCo's free joint) from its pose; without,
    it is fixed in the world. The robot's links touch it through their ``<collision>``
    shapes."""

    name: str
    geometry: Geometry
    pose: Pose
    mass: float = 0.0            # kg; 0: fixed in the world
    friction: float = 1.0        # sliding friction coefficient against what it touches
    line: int | None = None

    @property
    def movable(self) -> bool:
        return self.mass > 0


@dataclass(frozen=True)
class DriveConfig:
    """One drive on a bus; ``gains`` None means tuned from the plant's inertia."""

    node_id: int
    actuator: str
    joints: tuple[str, ...]
    protocol: str
    encoder_counts_per_rev: int
    rated_torque: float
    peak_torque: float
    max_velocity: float
    following_error_limit: float
    following_error_timeout: float
    quick_stop_deceleration: float
    watchdog_timeout: float
    heartbeat_period: float
    holding_brake: bool
    position_limits: tuple[float, float] | None
    gains: Gains | None
    velocity_bandwidth_hz: float
    options: ProtocolOptions | None = None     # the protocol's own settings
    line: int | None = None
    effects: ActuatorEffects = NO_EFFECTS
    #: the master adds the torque that holds the joints against gravity at the target
    #: (from the description: ``hil.hardware.gravity``) to each setpoint, in the protocol's
    #: own field (CiA 402 0x60B2, ODrive's Torque_FF, MIT's t_ff): ``gravity``; or ``none``
    torque_feed_forward: str = "none"
    #: its bus carries CAN FD (the bus' ``fd``): a family that follows the bus
    #: (:class:`~hil.protocols.base.CanFd`) sends FD frames with the bit-rate switch
    can_fd: bool = False

    @property
    def label(self) -> str:
        return f"node {self.node_id} ({', '.join(self.joints)})"


@dataclass(frozen=True)
class BusConfig:
    name: str
    interface: str
    channel: str
    bitrate: int
    cycle_hz: float
    drives: tuple[DriveConfig, ...]
    line: int | None = None
    #: CAN FD (ISO 11898-1:2015): FD frames may cross it, their data phase at
    #: ``data_bitrate`` bit/s where the bit-rate switch is set (None on a classical bus)
    fd: bool = False
    data_bitrate: int | None = None
    #: what the CAN sensors on it send (their TPDOs at their rates), for its load and ids
    sensor_frames: tuple[FrameSpec, ...] = ()

    @property
    def cycle(self) -> float:
        return 1.0 / self.cycle_hz

    @property
    def bit_rates(self) -> BitRates:
        return BitRates(self.bitrate, self.data_bitrate)

    @property
    def rates(self) -> str:
        """Its bit rates in words: "1,000 kbit/s", or "1,000 kbit/s CAN FD, 5,000 kbit/s
        data"."""
        nominal = f"{self.bitrate / 1e3:,.0f} kbit/s"
        if not self.fd:
            return nominal
        return f"{nominal} CAN FD, {self.data_bitrate / 1e3:,.0f} kbit/s data"

    @property
    def protocols(self) -> tuple[type[Protocol], ...]:
        """The protocols of its drives, each once, in the drives' order."""
        return tuple(dict.fromkeys(protocol(d.protocol) for d in self.drives))

    def bus_wide_frames(self) -> list[FrameSpec]:
        """The frames of the bus as a whole (CANopen's NMT and SYNC), each of its protocols'
        once however many of its drives the bus has."""
        return [spec for kind in self.protocols for spec in kind.bus_wide_frames(self.cycle_hz)]

    @property
    def cycle_end_frames(self) -> tuple[Frame, ...]:
        """What the master sends on the bus after every cycle's frames (CANopen: SYNC), each
        of its protocols' once."""
        return tuple(frame for kind in self.protocols for frame in kind.cycle_end_frames)

    def frames(self, drive: DriveConfig, node_id: int | None = None) -> list[FrameSpec]:
        """One drive's traffic, as its profile says (as node ``node_id`` where given, else its
        own)."""
        spec = protocol(drive.protocol)
        node_id = drive.node_id if node_id is None else node_id
        frames = spec.bus_frames(node_id, self.cycle_hz, drive.heartbeat_period, drive.options)
        if drive.torque_feed_forward != "none":
            frames += spec.torque_feed_forward_frames(node_id, self.cycle_hz, drive.options)
        return spec.on_bus(frames, self.fd)

    def running_frames(self, drive: DriveConfig) -> list[FrameSpec]:
        """The drive's traffic once it runs: one that boots waiting for a master to assign
        its node id (LSS) is counted with the exchange it has after that (payloads and rates
        do not depend on the id, so any configured id stands for it)."""
        spec = protocol(drive.protocol)
        if drive.node_id == spec.unconfigured_node_id:
            return self.frames(drive, min(spec.node_ids))
        return self.frames(drive)

    def frame_owner(self, frame: Frame) -> str | None:
        """Which drive of the bus a frame is from or for, in words ("node 3, RPDO1"), as its
        protocol tells by the frame (:meth:`Protocol.frame_source`); None where none does."""
        for kind in self.protocols:
            drives = {d.node_id: d.options for d in self.drives if d.protocol == kind.name}
            try:
                source = kind.frame_source(frame, drives)
            except NotImplementedError:
                continue
            if source is not None:
                node = "every node" if source.node_id is None else f"node {source.node_id}"
                return f"{node}, {source.what}"
        return None

    def load(self) -> BusLoad:
        """Worst-case traffic of every drive's cyclic exchange and timed messages (each
        profile's own frames and lengths) once running, plus the bus-wide frames of its
        protocols (CANopen's SYNC) and its sensors' frames."""
        specs = self.bus_wide_frames() + list(self.sensor_frames)
        for drive in self.drives:
            specs += self.running_frames(drive)
        return bus_load(self.bitrate, [spec for spec in specs if spec.rate > 0],
                        self.data_bitrate)


@dataclass(frozen=True)
class ControllersSource:
    """The bus config's ``controllers:`` (hil.bus_config.controllers_key): the user's
    controller_manager YAML and how its names meet this bench."""

    path: Path
    #: (name in the file, the bench's joint) pairs; a name not listed is the joint's own
    joint_names: tuple[tuple[str, str], ...] = ()
    #: the values of the file's $(var NAME) substitutions
    variables: tuple[tuple[str, str], ...] = ()
    #: the controllers active from the start (None: the file's trajectory controller)
    active: tuple[str, ...] | None = None
    line: int | None = None


@dataclass(frozen=True)
class SystemConfig:
    """A whole bench: robot, plant rate, buses."""

    path: Path
    robot: RobotDescription
    plant_rate_hz: float
    buses: tuple[BusConfig, ...]
    warnings: tuple[Diagnostic, ...] = field(default=(), compare=False)
    scene: tuple[SceneObject, ...] = ()
    #: the robot's root free (MuJoCo's free joint: it stands on the scene, as a legged or
    #: mobile robot does), not welded to the world (``base: floating``)
    floating_base: bool = False
    #: where joints start (``start_pose:``), (joint, position) pairs; the rest hil's way
    start_pose: tuple[tuple[str, float], ...] = ()
    #: the user's controller_manager YAML (``controllers:``), or None: hil's own controllers
    controllers: ControllersSource | None = None
    #: the sensors on the robot's links (``sensors:``, docs/sensors.md)
    sensors: tuple[Sensor, ...] = ()

    @property
    def imus(self) -> tuple[ImuConfig, ...]:
        """Its IMUs, in config order."""
        return tuple(s for s in self.sensors if isinstance(s, ImuConfig))

    @property
    def force_torques(self) -> tuple[ForceTorqueConfig, ...]:
        """Its force-torque sensors, in config order."""
        return tuple(s for s in self.sensors if isinstance(s, ForceTorqueConfig))

    @property
    def effects(self) -> dict[str, ActuatorEffects]:
        """Each actuator's effects, where its drive sets any."""
        return {d.actuator: d.effects for d in self.drives if d.effects.in_force()}

    @property
    def cycle_hz(self) -> float:
        return self.buses[0].cycle_hz

    @property
    def drives(self) -> tuple[DriveConfig, ...]:
        return tuple(d for bus in self.buses for d in bus.drives)

    @property
    def steps_per_cycle(self) -> int:
        return round(self.plant_rate_hz / self.cycle_hz)
