"""Robstride RS00-RS06 and Xiaomi CyberGear actuators on CAN, as their makers document them.

The documents (docs/protocols/robstride.md lists every message and what hil does with it):

* the CyberGear instruction manual §4 (belovictor/cybergear-docs, its English text): the
  private protocol, types 0-4, 6, 7, 17, 18, 21 and 22 (baud rate), the parameter table
  §4.1.12, the control modes §4.2;
* the Robstride manuals (RS00 manual 260112, its private and MIT protocol chapters) and the
  maker's code (RobStride/SampleProgram ``RS/RobStride.h``, ``Robstride01.cpp``): the same
  private protocol with types 22 save, 23 baud rate, 24 active reporting and 25 protocol
  switch, run modes 1 PP and 5 CSP, and an MIT protocol mode on 11-bit ids.

Where they differ, the model says which a drive follows (``RobstrideModel.cybergear``):
a CyberGear takes type 22 as its baud-rate change and knows no types 23-25 and no MIT
protocol mode; its run mode 1 follows ``loc_ref`` at ``limit_spd`` (the RS firmware's 5,
CSP). The codec is :mod:`.codec`, the parameter table :mod:`.params`.
"""

from __future__ import annotations

import enum
from collections.abc import Mapping
from dataclasses import dataclass

from hil.can.frame import Frame, FrameSpec
from hil.protocols.base import (CarriedRange, DriveSetting, FrameSource, Protocol,
                                ProtocolOptions, Sender)
from hil.protocols.mit.family import parse_model, parse_ranges
from hil.protocols.robstride.codec import (
    BROADCAST, DEFAULT_HOST, Comm, PrivateId, Ranges, mit_command_id, private_id,
)
from hil.protocols.robstride.models import MODELS, SIZED, RobstrideModel, model


class Framing(enum.Enum):
    """The protocol a motor boots in (``protocol`` of its options): the factory's private
    protocol, or the MIT protocol mode a type 25 frame and a power cycle switch it to."""

    PRIVATE = "private"
    MIT = "mit"


def framing_of(protocol: int) -> Framing | None:
    """The framing a protocol code (type 25's byte 6, MIT command 8) boots in; None:
    CANopen, which hil does not simulate (the motor then answers none of its private or MIT
    frames)."""
    return {0: Framing.PRIVATE, 2: Framing.MIT}.get(protocol)


#: the master's requests (to the motor, its id in bits 7-0) by type, in the makers' words
REQUESTS = {Comm.GET_DEVICE_ID: "get device id", Comm.MOTION_CONTROL: "motion control",
            Comm.ENABLE: "enable", Comm.STOP: "stop", Comm.SET_ZERO: "set mechanical zero",
            Comm.SET_CAN_ID: "set CAN id", Comm.READ_PARAMETER: "read parameter",
            Comm.WRITE_PARAMETER: "write parameter", Comm.FAULT_FEEDBACK: "fault request",
            Comm.SAVE_PARAMETERS: "save parameters", Comm.BAUD_RATE: "baud rate",
            Comm.ACTIVE_REPORTING: "active reporting", Comm.PROTOCOL: "protocol switch"}
#: the motor's frames by type
ANSWERS = {Comm.GET_DEVICE_ID: "device id", Comm.FEEDBACK: "feedback",
           Comm.READ_PARAMETER: "parameter", Comm.FAULT_FEEDBACK: "fault feedback"}
#: MIT protocol mode: the command ids' modes (RS00 manual, MIT §4.2)
MIT_MODES = {0: "MIT command", 1: "position control", 2: "speed control"}


@dataclass(frozen=True)
class RobstrideOptions(ProtocolOptions):
    """A Robstride or CyberGear motor's settings in a bus config (``options:``)."""

    model: RobstrideModel = MODELS["RS03"]
    protocol: Framing = Framing.PRIVATE
    #: the host id the motor answers (MIT mode: the answers' 11-bit id)
    host_id: int = DEFAULT_HOST
    #: the mapping ranges (default: the model's)
    p_max: float | None = None
    v_max: float | None = None
    t_max: float | None = None
    #: the gains hil's own master sends in operation control (output side)
    kp: float = 0.0
    kd: float = 0.0

    KEYS = ("model", "protocol", "host_id", "p_max", "v_max", "t_max", "kp", "kd")
    #: off: canTimeout (0x7028) ships 0, "0 = disabled" (RS00 manual, parameter table)
    WATCHDOG_TIMEOUT = 0.0

    @classmethod
    def from_mapping(cls, values: dict) -> RobstrideOptions:
        """Raise ValueError naming the key for anything out of range."""
        found = parse_model(values, model, MODELS["RS03"])
        try:
            framing = Framing(str(values.get("protocol", "private")).lower())
        except ValueError:
            raise ValueError(f"'protocol' {values['protocol']!r} is not one of private, mit "
                             "(hil simulates no CANopen mode)") from None
        if framing is Framing.MIT and found.cybergear:
            raise ValueError("a CyberGear has no MIT protocol mode (its manual §4 knows the "
                             "private protocol only): protocol: private")
        host = int(values.get("host_id", DEFAULT_HOST))
        if not 0 <= host <= 0xFF:
            raise ValueError(f"'host_id' {host} is not a one-byte id (0-255)")
        kp, kd = float(values.get("kp", 0.0)), float(values.get("kd", 0.0))
        if not (0 <= kp <= found.kp_max and 0 <= kd <= found.kd_max):
            raise ValueError(f"'kp' must be in [0, {found.kp_max:g}] and 'kd' in "
                             f"[0, {found.kd_max:g}] for the {found.name}")
        return cls(found, framing, host, kp=kp, kd=kd, **parse_ranges(values))

    def drive_defaults(self) -> dict[str, float | bool]:
        """The model's published output figures where the sources give them."""
        if not self.model.sizes:
            return super().drive_defaults()
        return {**super().drive_defaults(), "peak_torque": self.model.peak_torque,
                "rated_torque": self.model.rated_torque,
                "max_velocity": self.model.no_load_speed, "holding_brake": False}

    def carried_range(self) -> CarriedRange:
        ranges = self.ranges()
        return CarriedRange(ranges.p_max, ranges.v_max)

    def ranges(self) -> Ranges:
        found = self.model
        return Ranges(self.p_max or found.p_max, self.v_max or found.v_max,
                      self.t_max or found.t_max, found.kp_max, found.kd_max)


class Robstride(Protocol):
    """Robstride and CyberGear actuators: the private protocol, or Robstride's MIT mode."""

    name = "robstride"
    Options = RobstrideOptions
    carries_torque_feed_forward = True
    has_following_error = False
    #: CAN_ID (0x200A) is 0-127 (CyberGear §3.3.3); the MIT mode's 11-bit ids keep to 0x7F
    #: (SampleProgram README: "standard frame CAN ID range 0x00-0x7F")
    node_ids = range(1, 128)
    models = SIZED
    drive = "hil.protocols.robstride.drive:RobstrideDrive"
    axis = "hil.protocols.robstride.axis:RobstrideAxis"

    @classmethod
    def initial_options(cls, setting: DriveSetting) -> dict:
        """The model (sized for the drive, else the RS03) and the master's operation-control
        gains within its ranges."""
        found = MODELS[setting.model or "RS03"]
        return {"model": found.name, "kp": float(f"{min(setting.kp, found.kp_max):.4g}"),
                "kd": float(f"{min(setting.kd, found.kd_max):.4g}")}

    @classmethod
    def bus_frames(cls, node_id: int, cycle_hz: float, heartbeat_period: float,
                   options: RobstrideOptions | None = None) -> list[FrameSpec]:
        """Private: a motion-control command a cycle and its feedback, the other types on
        events (the torque field of type 1, the fault and mode bits of type 2 vary: the
        ids given are at zero torque and in run mode). MIT mode: the 11-bit frames."""
        options = options or RobstrideOptions()
        host = options.host_id
        if options.protocol is Framing.MIT:
            return [FrameSpec(mit_command_id(0, node_id), 8, cycle_hz, "MIT command"),
                    FrameSpec(host, 8, cycle_hz, "answer"),
                    FrameSpec(mit_command_id(1, node_id), 8, 0, "position control"),
                    FrameSpec(mit_command_id(2, node_id), 8, 0, "speed control")]
        frames = [FrameSpec(private_id(Comm.MOTION_CONTROL, 0x7FFF, node_id), 8, cycle_hz,
                            "motion control", extended=True),
                  FrameSpec(private_id(Comm.FEEDBACK, 2 << 14 | node_id, host), 8, cycle_hz,
                            "feedback", extended=True),
                  FrameSpec(private_id(Comm.GET_DEVICE_ID, node_id, BROADCAST), 8, 0,
                            "device id", extended=True),
                  FrameSpec(private_id(Comm.READ_PARAMETER, node_id, host), 8, 0,
                            "parameter", extended=True)]
        frames += [FrameSpec(private_id(comm, host, node_id), 8, 0, what, extended=True)
                   for comm, what in REQUESTS.items() if comm is not Comm.MOTION_CONTROL
                   and comm <= cls._last_type(options.model)]
        return frames

    @staticmethod
    def _last_type(found: RobstrideModel) -> int:
        """CyberGear's manual ends at type 22 (§4.1.11)."""
        return Comm.SAVE_PARAMETERS if found.cybergear else Comm.PROTOCOL

    @classmethod
    def frame_source(cls, frame: Frame, drives: Mapping[int, object]) -> FrameSource | None:
        """Private (extended): the master's requests name the motor in bits 7-0 and its host
        in bits 15-8; the motor's frames name it in bits 15-8 (type 2, 17, 21; type 0's
        answer to 0xFE). MIT mode (11-bit): commands on ``mode << 8 | id``, answers on the
        host id naming the motor in byte 0."""
        if frame.extended:
            return cls._private_source(PrivateId.of(frame.identifier), drives)
        mit = {node: options for node, options in drives.items()
               if (options or RobstrideOptions()).protocol is Framing.MIT}
        identifier = frame.identifier
        node, mode = identifier & 0xFF, identifier >> 8
        if node in mit and mode in MIT_MODES:
            return FrameSource(Sender.MASTER, node, MIT_MODES[mode], cycle=True)
        data = frame.data
        hosts = {(options or RobstrideOptions()).host_id for options in mit.values()}
        if identifier in hosts and data and data[0] in mit:
            return FrameSource(Sender.DRIVE, data[0], "answer")
        return None

    @classmethod
    def _private_source(cls, found: PrivateId, drives: Mapping[int, object]
                        ) -> FrameSource | None:
        """A motor's frame names it in bits 15-8 and a host (or 0xFE) that is no motor of
        the bus in bits 7-0; a request names the motor in bits 7-0."""
        motor = found.data & 0xFF
        if found.comm in ANSWERS and motor in drives and found.target not in drives and (
                found.comm != Comm.GET_DEVICE_ID or found.target == BROADCAST):
            return FrameSource(Sender.DRIVE, motor, ANSWERS[Comm(found.comm)])
        if found.comm in REQUESTS and found.target in drives:
            return FrameSource(Sender.MASTER, found.target, REQUESTS[Comm(found.comm)],
                               cycle=found.comm == Comm.MOTION_CONTROL)
        return None

    @classmethod
    def shared_ids(cls, options: RobstrideOptions | None = None) -> set[int]:
        """MIT mode: every motor answers on the host id (byte 0 tells whose)."""
        options = options or RobstrideOptions()
        return {options.host_id} if options.protocol is Framing.MIT else set()


__all__ = ["ANSWERS", "MIT_MODES", "REQUESTS", "Framing", "Robstride", "RobstrideOptions",
           "framing_of"]
