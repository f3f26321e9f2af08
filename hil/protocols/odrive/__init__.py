"""ODrive CANSimple (firmware 0.6, ODrive Pro / S1 / Micro): frames, codec, options.

Frames: 11-bit id ``node_id << 5 | cmd_id``, little-endian payloads, IEEE-754
floats, positions in turns (rev) and velocities in rev/s of the motor, torques
in N·m. ``Get_*`` messages are sent on request (an RTR frame with the same id)
and, where configured, cyclically (heartbeat always). The layouts are
``odrive-cansimple-0.6.10.dbc`` (ODrive's own DBC, shipped in the PyPI package
``odrive-can``); the tests check both directions against it with cantools.
They are packed here with ``struct`` because they run every cycle.

Errors as an ODrive reports them: a violated limit, an expired watchdog or an
estop disarms the axis (IDLE) with the error in ``active_errors`` and as the
``disarm_reason``, in every heartbeat, until ``Clear_Errors``.
"""

from __future__ import annotations

import enum
import math
import struct
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path

from hil.can.frame import Frame, FrameSpec
from hil.protocols.base import (DriveSetting, FrameSource, Protocol, ProtocolOptions, Sender,
                                SettingField)
from hil.protocols.odrive.endpoints import EndpointFile, load_endpoints

TURN = 2 * math.pi
#: the unaddressed node, whose Address id every ODrive hears (ODrive's CAN protocol page)
BROADCAST_NODE_ID = 0x3F
#: V: the simulated supply (Get_Bus_Voltage_Current, ``vbus_voltage``)
BUS_VOLTAGE = 24.0
#: the serial numbers hil gives drives without ``serial_number``: "HIL" and the node id
#: (hil's choice: the maker's are the MCU's unique id, 48 bits)
SERIAL_NUMBER_BASE = 0x48494C000000


class Cmd(enum.IntEnum):
    """CANSimple command ids (the low 5 bits of the arbitration id)."""

    GET_VERSION = 0x00
    HEARTBEAT = 0x01
    ESTOP = 0x02
    GET_ERROR = 0x03
    RX_SDO = 0x04
    TX_SDO = 0x05
    ADDRESS = 0x06
    SET_AXIS_STATE = 0x07
    GET_ENCODER_ESTIMATES = 0x09
    SET_CONTROLLER_MODE = 0x0B
    SET_INPUT_POS = 0x0C
    SET_INPUT_VEL = 0x0D
    SET_INPUT_TORQUE = 0x0E
    SET_LIMITS = 0x0F
    SET_TRAJ_VEL_LIMIT = 0x11
    SET_TRAJ_ACCEL_LIMITS = 0x12
    SET_TRAJ_INERTIA = 0x13
    GET_IQ = 0x14
    GET_TEMPERATURE = 0x15
    REBOOT = 0x16
    GET_BUS_VOLTAGE_CURRENT = 0x17
    CLEAR_ERRORS = 0x18
    SET_ABSOLUTE_POSITION = 0x19
    SET_POS_GAIN = 0x1A
    SET_VEL_GAINS = 0x1B
    GET_TORQUES = 0x1C
    GET_POWERS = 0x1D


#: payload layouts (struct formats, padded to the DBC's length)
LAYOUT = {
    Cmd.GET_VERSION: struct.Struct("<BBBBBBBB"),
    Cmd.HEARTBEAT: struct.Struct("<IBBBx"),        # axis error, state, procedure, traj done
    Cmd.GET_ERROR: struct.Struct("<II"),           # active errors, disarm reason
    Cmd.SET_AXIS_STATE: struct.Struct("<I4x"),
    Cmd.GET_ENCODER_ESTIMATES: struct.Struct("<ff"),   # pos (rev), vel (rev/s)
    Cmd.SET_CONTROLLER_MODE: struct.Struct("<II"),     # control mode, input mode
    Cmd.SET_INPUT_POS: struct.Struct("<fhh"),      # pos (rev), vel ff, torque ff (x 0.001)
    Cmd.SET_INPUT_VEL: struct.Struct("<ff"),       # vel (rev/s), torque ff (N·m)
    Cmd.SET_INPUT_TORQUE: struct.Struct("<f4x"),
    Cmd.SET_LIMITS: struct.Struct("<ff"),          # velocity limit (rev/s), current limit (A)
    Cmd.SET_TRAJ_VEL_LIMIT: struct.Struct("<f4x"),     # rev/s
    Cmd.SET_TRAJ_ACCEL_LIMITS: struct.Struct("<ff"),   # accel, decel (rev/s^2)
    Cmd.SET_TRAJ_INERTIA: struct.Struct("<f4x"),       # N·m / (rev/s^2)
    Cmd.SET_ABSOLUTE_POSITION: struct.Struct("<f4x"),  # rev
    Cmd.SET_POS_GAIN: struct.Struct("<f4x"),           # (rev/s) / rev
    Cmd.SET_VEL_GAINS: struct.Struct("<ff"),           # N·m / (rev/s), N·m / rev
    Cmd.GET_IQ: struct.Struct("<ff"),              # setpoint, measured (A)
    Cmd.GET_TEMPERATURE: struct.Struct("<ff"),     # FET, motor (deg C)
    Cmd.REBOOT: struct.Struct("<B"),
    Cmd.GET_BUS_VOLTAGE_CURRENT: struct.Struct("<ff"),
    Cmd.CLEAR_ERRORS: struct.Struct("<B"),
    Cmd.GET_TORQUES: struct.Struct("<ff"),         # target, estimate (N·m)
    Cmd.GET_POWERS: struct.Struct("<ff"),          # electrical, mechanical (W)
}


class AxisState(enum.IntEnum):
    UNDEFINED = 0
    IDLE = 1
    STARTUP_SEQUENCE = 2
    FULL_CALIBRATION_SEQUENCE = 3
    MOTOR_CALIBRATION = 4
    ENCODER_INDEX_SEARCH = 6
    ENCODER_OFFSET_CALIBRATION = 7
    CLOSED_LOOP_CONTROL = 8


class ControlMode(enum.IntEnum):
    VOLTAGE_CONTROL = 0
    TORQUE_CONTROL = 1
    VELOCITY_CONTROL = 2
    POSITION_CONTROL = 3


class InputMode(enum.IntEnum):
    """``controller.config.input_mode``: how an input becomes the controller's setpoint."""

    INACTIVE = 0
    PASSTHROUGH = 1
    VEL_RAMP = 2
    POS_FILTER = 3
    MIX_CHANNELS = 4
    TRAP_TRAJ = 5
    TORQUE_RAMP = 6
    MIRROR = 7
    TUNING = 8


class ODriveError(enum.IntFlag):
    """ODrive 0.6 axis errors (the subset a simulated axis can raise)."""

    NONE = 0
    MISSING_INPUT = 0x40
    CURRENT_LIMIT_VIOLATION = 0x1000
    VELOCITY_LIMIT_VIOLATION = 0x8000
    POSITION_LIMIT_VIOLATION = 0x10000
    WATCHDOG_TIMER_EXPIRED = 0x1000000
    ESTOP_REQUESTED = 0x2000000


#: the command ids whose data frames an axis sends (the answers to RTRs, the heartbeat); a
#: master sends every other one, and the RTRs
AXIS_SENDS = frozenset({Cmd.GET_VERSION, Cmd.HEARTBEAT, Cmd.GET_ERROR, Cmd.TX_SDO, Cmd.ADDRESS,
                        Cmd.GET_ENCODER_ESTIMATES, Cmd.GET_IQ, Cmd.GET_TEMPERATURE,
                        Cmd.GET_BUS_VOLTAGE_CURRENT, Cmd.GET_TORQUES, Cmd.GET_POWERS})


def can_id(node_id: int, cmd: int) -> int:
    return (node_id << 5) | cmd


def command_name(cmd: int) -> str:
    """A command id in the words of ODrive's DBC ("Set_Input_Pos"); an unknown one by its
    number."""
    return Cmd(cmd).name.title() if cmd in Cmd.__members__.values() else f"cmd 0x{cmd:02X}"


#: each cyclic message's rate option (``axis.config.can.*_msg_rate_ms``) and its message
RATE_OPTIONS = {"encoder_msg_rate_ms": Cmd.GET_ENCODER_ESTIMATES,
                "torques_msg_rate_ms": Cmd.GET_TORQUES, "error_msg_rate_ms": Cmd.GET_ERROR,
                "iq_msg_rate_ms": Cmd.GET_IQ, "temperature_msg_rate_ms": Cmd.GET_TEMPERATURE,
                "bus_voltage_msg_rate_ms": Cmd.GET_BUS_VOLTAGE_CURRENT,
                "powers_msg_rate_ms": Cmd.GET_POWERS}


@dataclass(frozen=True)
class ODriveOptions(ProtocolOptions):
    """An ODrive axis' CAN settings (``axis.config.can.*``) in a bus config; rates in
    ms, 0 = only on request (RTR). Defaults as firmware 0.6 ships (ODrive's CAN protocol
    page: "cyclic messages ... encoder estimates every 10 ms, the others disabled"; the
    heartbeat is the drive's ``heartbeat_period``)."""

    encoder_msg_rate_ms: int = 10
    torques_msg_rate_ms: int = 0
    error_msg_rate_ms: int = 0
    iq_msg_rate_ms: int = 0
    temperature_msg_rate_ms: int = 0
    bus_voltage_msg_rate_ms: int = 0
    powers_msg_rate_ms: int = 0
    torque_constant: float = 0.0827   # N·m/A (8.27 / KV, KV 100)
    #: the user's flat_endpoints.json (ODrive's, of the firmware release to simulate): the
    #: endpoints served over RxSdo/TxSdo and the versions Get_Version gives; None: no
    #: endpoint is answered
    endpoints: Path | None = None
    #: the 48-bit serial number Address gives (None: SERIAL_NUMBER_BASE + node id)
    serial_number: int | None = None
    #: the endpoints file as read (from ``endpoints``)
    endpoint_file: EndpointFile | None = field(default=None, compare=False, repr=False)

    KEYS = (*RATE_OPTIONS, "torque_constant", "endpoints", "serial_number")
    #: the watchdog off, as the firmware ships (``axis.config.enable_watchdog`` false): a
    #: bus config's ``watchdog_timeout`` turns it on
    WATCHDOG_TIMEOUT = 0.0
    PATH_KEYS = ("endpoints",)

    @classmethod
    def from_mapping(cls, values: dict) -> ODriveOptions:
        values = dict(values)
        endpoints, serial = values.pop("endpoints", None), values.pop("serial_number", None)
        if endpoints is not None and not isinstance(endpoints, str):
            raise ValueError(f"'endpoints' is the path of a flat_endpoints.json, not "
                             f"{endpoints!r}")
        if serial is not None and (not isinstance(serial, int) or isinstance(serial, bool)
                                   or not 0 <= serial < 2**48):
            raise ValueError(f"'serial_number' is 48 bits (0..{2**48 - 1}), not {serial!r}")
        options = cls(**{k: (float(v) if k == "torque_constant" else int(v))
                         for k, v in values.items()},
                      endpoints=Path(endpoints) if endpoints is not None else None,
                      serial_number=serial,
                      endpoint_file=load_endpoints(Path(endpoints)) if endpoints else None)
        if options.torque_constant <= 0:
            raise ValueError("'torque_constant' must be > 0")
        if any(not 0 <= getattr(options, k) < 2**32 for k in RATE_OPTIONS):
            # the firmware's axis.config.can.*_msg_rate_ms are uint32 (odrive-interface.yaml)
            raise ValueError("message rates must be 0..4294967295 ms")
        return options

    def rates(self) -> dict[Cmd, float]:
        """Cyclic messages (besides the heartbeat) and their periods in s."""
        return {cmd: getattr(self, key) / 1000 for key, cmd in RATE_OPTIONS.items()
                if getattr(self, key) > 0}


class ODrive(Protocol):
    """ODrive axes on CANSimple: node ids 0-62, no SYNC."""

    name = "odrive"
    Options = ODriveOptions
    carries_torque_feed_forward = True
    #: 6-bit node ids; 0x3F is the broadcast's and an unaddressed axis' (ODrive's library
    #: discovers by asking node 63's Address; odrive-messages calls 0x3F
    #: UNADDRESSED_NODE_ID), so no configured axis has it
    node_ids = range(0, BROADCAST_NODE_ID)
    has_following_error = False
    setting_fields = {"heartbeat_period": SettingField(
        1000, 1, 0xFFFFFFFF, "axis.config.can.heartbeat_msg_rate_ms, uint32 ms")}
    drive = "hil.protocols.odrive.drive:ODriveDrive"
    axis = "hil.protocols.odrive.axis:ODriveAxis"

    @classmethod
    def initial_options(cls, setting: DriveSetting) -> dict:
        """No cyclic encoder estimates: hil's master asks for them with an RTR each cycle
        (the firmware's 10 ms ones would arrive mid-cycle)."""
        return {"encoder_msg_rate_ms": 0}

    @classmethod
    def frame_source(cls, frame: Frame, drives: Mapping[int, object]) -> FrameSource | None:
        if frame.extended:
            # hil's axes have 11-bit ids (node 0..0x3F, ODrive's CAN protocol page); the
            # firmware's extended ids (``can_node_id_extended``) are not simulated
            return None
        node, cmd = frame.identifier >> 5, frame.identifier & 0x1F
        if node == BROADCAST_NODE_ID and cmd == Cmd.ADDRESS and node not in drives:
            # discovery's RTR and a client's set-address / connect, to every ODrive
            return FrameSource(Sender.MASTER, None,
                               "Address request" if frame.remote else "Address")
        if node not in drives:
            return None
        name = command_name(cmd)
        if frame.remote:   # the cyclic master's Get_Encoder_Estimates RTR is a cycle's request
            return FrameSource(Sender.MASTER, node, f"{name} request",
                               cycle=cmd == Cmd.GET_ENCODER_ESTIMATES)
        return FrameSource(Sender.DRIVE if cmd in AXIS_SENDS else Sender.MASTER, node, name)

    @classmethod
    def source_reads_data(cls, frame: Frame, drives: Mapping[int, object]) -> bool:
        return False                       # the id is node and command

    @classmethod
    def bus_frames(cls, node_id: int, cycle_hz: float, heartbeat_period: float,
                   options: ODriveOptions | None = None) -> list[FrameSpec]:
        """A cyclic master's exchange: Set_Input_Pos, RTR + answer for Get_Torques and
        Get_Encoder_Estimates per cycle; the heartbeat and configured cyclic messages;
        every other command id is reserved for events."""
        options = options or ODriveOptions()
        rates = {Cmd.SET_INPUT_POS: cycle_hz, Cmd.HEARTBEAT: 1.0 / heartbeat_period}
        result = [FrameSpec(can_id(node_id, cmd), 8 if cmd in rates else 0, rates.get(cmd, 0.0),
                            command_name(cmd)) for cmd in Cmd]
        for cmd in (Cmd.GET_TORQUES, Cmd.GET_ENCODER_ESTIMATES):     # the master's RTR + answer
            name = command_name(cmd)
            result += [FrameSpec(can_id(node_id, cmd), 8, cycle_hz, name),
                       FrameSpec(can_id(node_id, cmd), 0, cycle_hz, f"{name} request")]
        result += [FrameSpec(can_id(node_id, cmd), 8, 1.0 / period, command_name(cmd))
                   for cmd, period in options.rates().items()]
        return result
