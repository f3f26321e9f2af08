"""mjbots' moteus controllers (r4, c1, n1, x1) on CAN FD, as the maker's document and
firmware speak (github.com/mjbots/moteus: docs/protocol/can.md, docs/protocol/registers.md,
fw/moteus_controller.cc, fw/fdcan_micro_server.h).

* Frames: CAN FD, 1 Mbit/s nominal and 5 Mbit/s data (can.md "CAN Format"). The identifier
  is 16 bits (can.md "CAN ID"): the destination (the controller's 7-bit id) in the low byte,
  the source in the high one, whose top bit (0x8000) asks for a reply; a 13-bit prefix may
  sit above (bits 16-28, the library's ``can_prefix``, the firmware's ``can.prefix``). A
  frame is extended where its identifier does not fit 11 bits. 0x7F is every controller
  (mjlib ``kBroadcastId``).
* Payload: register subframes (:mod:`hil.protocols.moteus.multiplex`) over the registers
  of :mod:`hil.protocols.moteus.registers`, padded with 0x50 to a CAN FD length.
* A reply goes from the controller's id to the asker's, with the asker's prefix, as FD
  frame where the request was one (or the reply is longer than 8 bytes) and with the
  bit-rate switch where the request had it (fw/fdcan_micro_server.h ``AsyncWrite``).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass

from hil.can.frame import Frame, FrameSpec
from hil.protocols.base import (
    CanFd, DriveSetting, FrameSource, Protocol, ProtocolOptions, Sender,
)
from hil.protocols.moteus import multiplex
from hil.protocols.moteus.models import (
    CONTROLLERS, DEFAULT_CONTROLLER, MODELS, MOTORS, Controller, MoteusModel, Motor, find,
)
from hil.protocols.moteus.registers import FLOAT, INT8, Mode, Register

REPLY_REQUESTED = 0x8000
BROADCAST = 0x7F
PREFIXES = 0x1FFF
TURN = 2 * math.pi           # rad per revolution: moteus counts revolutions at its output


def identifier(source: int, destination: int, reply: bool = False, prefix: int = 0) -> int:
    """The arbitration id of a frame (can.md "CAN ID"; the library's ``_command_to_frame``)."""
    return (prefix << 16) | (REPLY_REQUESTED if reply else 0) | (source << 8) | destination


def moteus_frame(can_id: int, payload: bytes, fd: bool = True, brs: bool = True) -> Frame:
    """A frame of the protocol: padded with NOPs to its length, extended where the id needs
    29 bits (fw/fdcan.cc ``Send``: ``dest_id >= 2048``)."""
    data = multiplex.pad(payload) if fd else payload
    return Frame(can_id, data, extended=can_id > 0x7FF, fd=fd, bitrate_switch=fd and brs)


def position_command(position: float, velocity: float, torque: float) -> bytes:
    """Position mode (mode 10, written first: registers.md "0x000 - Mode") with position,
    velocity (rev, Hz) and feed-forward torque (N·m) as floats in 0x020-0x022."""
    return (multiplex.write(INT8, Register.MODE, [Mode.POSITION])
            + multiplex.write(FLOAT, Register.COMMAND_POSITION, [position, velocity, torque]))


STOP = multiplex.write(INT8, Register.MODE, [Mode.STOPPED])
#: what hil's master reads back each cycle: mode (int8), position, velocity and torque
#: (float), fault (int8): the moteus library's default query less voltage and temperature
QUERY = (multiplex.read(INT8, Register.MODE, 1) + multiplex.read(FLOAT, Register.POSITION, 3)
         + multiplex.read(INT8, Register.FAULT, 1))


def _int(values: Mapping, key: str, default: int, top: int) -> int:
    value = values.get(key, default)
    if not (isinstance(value, int) and 0 <= value <= top):
        raise ValueError(f"'{key}' {value!r} is not an integer in 0..{top}")
    return value


@dataclass(frozen=True)
class MoteusOptions(ProtocolOptions):
    """A moteus' settings in a bus config (``options:`` of the drive)."""

    motor: Motor = MOTORS["mj5208"]
    controller: Controller = CONTROLLERS[DEFAULT_CONTROLLER]
    #: ``servo.pid_position.kp`` (N·m/rev) and ``kd`` (N·m·s/rev) at the output; the
    #: firmware's defaults 4.0 and 0.05 (fw/bldc_servo_structs.h BldcServoConfig()); its
    #: ki is left out: ``ilimit`` 0 by default makes it do nothing
    kp: float = 4.0
    kd: float = 0.05
    #: ``can.prefix``: the 13 bits above the 16-bit id it answers (0: none)
    can_prefix: int = 0
    #: the source id hil's master sends from (the moteus library's ``source_can_id``, 0)
    master_id: int = 0

    KEYS = ("motor", "controller", "kp", "kd", "can_prefix", "master_id")
    #: ``servo.default_timeout_s`` as it ships, 0.1 s (fw/bldc_servo_structs.h;
    #: docs/reference/configuration.md)
    WATCHDOG_TIMEOUT = 0.1

    @classmethod
    def from_mapping(cls, values: dict) -> MoteusOptions:
        """Raise ValueError naming the key for anything out of range."""
        try:
            motor = find(MOTORS, "motor", str(values.get("motor", "mj5208")))
            controller = find(CONTROLLERS, "controller",
                              str(values.get("controller", DEFAULT_CONTROLLER)))
        except KeyError as exc:
            raise ValueError(exc.args[0]) from None
        kp, kd = float(values.get("kp", 4.0)), float(values.get("kd", 0.05))
        if not (kp >= 0 and kd >= 0):
            raise ValueError("'kp' and 'kd' must be >= 0 (N·m/rev, N·m·s/rev)")
        return cls(motor, controller, kp, kd, _int(values, "can_prefix", 0, PREFIXES),
                   _int(values, "master_id", 0, BROADCAST - 1))

    @property
    def model(self) -> MoteusModel:
        return MoteusModel(self.motor, self.controller)

    def drive_defaults(self) -> dict[str, float | bool]:
        """The motor's figures on its controller (:mod:`hil.protocols.moteus.models`); no
        holding brake (mjbots sells none); ``servo.default_timeout_s``."""
        model = self.model
        return {**super().drive_defaults(), "peak_torque": model.peak_torque,
                "rated_torque": model.rated_torque, "max_velocity": model.no_load_speed,
                "holding_brake": False}


class Moteus(Protocol):
    """moteus controllers: a register frame per controller per cycle, answered."""

    name = "moteus"
    Options = MoteusOptions
    #: 1..126: a controller's id is 7 bits, 0x7F every controller's (mjlib format.h)
    node_ids = range(1, BROADCAST)
    #: off unless ``servo.fault_position_error`` is set (NaN as it ships:
    #: fw/bldc_servo_structs.h)
    has_following_error = False
    carries_torque_feed_forward = True
    #: the axis reports the position timeout (mode 11) with that code
    link_loss_codes = frozenset({int(Mode.POSITION_TIMEOUT)})
    models = MODELS
    drive = "hil.protocols.moteus.drive:MoteusDrive"
    axis = "hil.protocols.moteus.axis:MoteusAxis"
    #: CAN FD only (can.md "CAN Format": 1 Mbit/s nominal, 5 Mbit/s data): no place on a
    #: classical bus (the bus config refuses it there)
    can_fd = CanFd.FD_ONLY

    @classmethod
    def initial_options(cls, setting: DriveSetting) -> dict:
        """The motor sized for the drive (else the mj5208) and the position loop's gains
        (hil's, per revolution: kp and kd of a critically damped loop on its inertia)."""
        return {"motor": setting.model or "mj5208", "controller": DEFAULT_CONTROLLER,
                "kp": float(f"{setting.kp * TURN:.4g}"), "kd": float(f"{setting.kd * TURN:.4g}")}

    @classmethod
    def bus_frames(cls, node_id: int, cycle_hz: float, heartbeat_period: float,
                   options: MoteusOptions | None = None) -> list[FrameSpec]:
        """hil's master: a position command with its query, and the reply, every cycle."""
        options = options or MoteusOptions()
        command = moteus_frame(identifier(options.master_id, node_id, True, options.can_prefix),
                               position_command(0.0, 0.0, 0.0) + QUERY)
        reply = moteus_frame(identifier(node_id, options.master_id, False, options.can_prefix),
                             multiplex.subframe(multiplex.REPLY, INT8, Register.MODE, 1) + b"\0"
                             + multiplex.subframe(multiplex.REPLY, FLOAT, Register.POSITION, 3)
                             + bytes(12)
                             + multiplex.subframe(multiplex.REPLY, INT8, Register.FAULT, 1)
                             + b"\0")
        return [FrameSpec(frame.identifier, frame.length, cycle_hz, what, frame.extended,
                          True, True)
                for frame, what in ((command, "position command + query"), (reply, "reply"))]

    @classmethod
    def frame_source(cls, frame: Frame, drives: Mapping[int, object]) -> FrameSource | None:
        """To a controller: its id in the low byte; from one: its id in the high byte's
        seven bits with no reply requested (a controller never asks)."""
        can_id = frame.identifier & 0xFFFF
        destination, source = can_id & 0xFF, (can_id >> 8) & 0x7F
        if source in drives and not can_id & REPLY_REQUESTED and destination not in drives:
            return FrameSource(Sender.DRIVE, source, "reply")
        if destination in drives:
            return FrameSource(Sender.MASTER, destination, "register frame", cycle=True)
        if destination == BROADCAST:
            return FrameSource(Sender.MASTER, None, "register frame to every controller")
        return None

    @classmethod
    def source_reads_data(cls, frame: Frame, drives: Mapping[int, object]) -> bool:
        return False                     # the id names source and destination


__all__ = ["BROADCAST", "QUERY", "REPLY_REQUESTED", "STOP", "TURN", "Moteus", "MoteusOptions",
           "identifier", "moteus_frame", "position_command"]
