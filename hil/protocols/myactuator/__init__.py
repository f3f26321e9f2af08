"""MyActuator RMD-X actuators on CAN, as the maker's *Motor Motion Control Command Protocol*
V4.2 (2024-05, for its V3 drivers) describes them; the frames byte for byte in
:mod:`.codec`, the models in :mod:`.models`.

Classical CAN at 1 Mbit/s, standard 11-bit ids, 8 data bytes (§1.1): commands to one motor
on ``0x140 + id``, answered on ``0x240 + id``; the multi-motor command on ``0x280``, which
every motor executes and answers on its own reply id (§3); the CANID setting command on
``0x300`` (§4); the motion mode (MIT) command on ``0x400 + id``, answered on ``0x500 + id``
(§5). hil's own master drives the motion mode (one frame a cycle, its reply carrying a
16-bit position); client libraries drive whatever commands they use.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

from hil.can.frame import Frame, FrameSpec
from hil.protocols.base import DriveSetting, FrameSource, Protocol, ProtocolOptions, Sender
from hil.protocols.myactuator.codec import (
    CANID_SETTING_ID, COMMAND_BASE, MIT_BASE, MIT_REPLY_BASE, MOTOR_IDS, MULTI_MOTOR_ID,
    REPLY_BASE, Command,
)
from hil.protocols.myactuator.models import MODELS, RmdModel, model

#: the model a drive is when its options name none, and ``hil init``'s without ``--motor``
DEFAULT_MODEL = "X8-20"
#: the version date 0xB2 answers (§2.29.4's example, 2022-02-06; hil's choice)
VERSION_DATE = 20220206


@dataclass(frozen=True)
class MyActuatorOptions(ProtocolOptions):
    """An RMD motor's settings in a bus config (``options:`` of the drive)."""

    model: RmdModel = MODELS[DEFAULT_MODEL]
    #: the supply voltage status 1 reports (V; 48: hil's choice, the X8's rated supply)
    supply_voltage: float = 48.0
    #: the gains hil's own master sends in motion mode commands (§5.1: kp 0-500, kd 0-5)
    kp: float = 0.0
    kd: float = 0.0

    KEYS = ("model", "supply_voltage", "kp", "kd")
    #: the communication interruption protection (0xB3, §2.30): "writing 0 means that the
    #: function is not enabled"; the document gives no factory value, hil ships it off
    WATCHDOG_TIMEOUT = 0.0

    @classmethod
    def from_mapping(cls, values: dict) -> MyActuatorOptions:
        """Raise ValueError naming the key for anything out of range."""
        try:
            found = model(str(values["model"])) if "model" in values else MODELS[DEFAULT_MODEL]
        except KeyError as exc:
            raise ValueError(exc.args[0]) from None
        volts = float(values.get("supply_voltage", 48.0))
        if not 0 < volts < 6553.5:
            raise ValueError(f"'supply_voltage' {volts:g} does not fit status 1's 0.1 V field")
        kp, kd = float(values.get("kp", 0.0)), float(values.get("kd", 0.0))
        if not (0 <= kp <= 500 and 0 <= kd <= 5):
            raise ValueError("'kp' must be in [0, 500] and 'kd' in [0, 5] (the motion "
                             "mode's ranges, §5.1)")
        return cls(found, volts, kp, kd)

    def drive_defaults(self) -> dict[str, float | bool]:
        """The model's figures; no holding brake (the SDK's models list none); the CAN
        timeout off."""
        return {**super().drive_defaults(), "peak_torque": float(self.model.peak_torque),
                "rated_torque": float(self.model.rated_torque),
                "max_velocity": self.model.no_load_speed, "holding_brake": False}


def command_id(node_id: int) -> int:
    return COMMAND_BASE + node_id


def reply_id(node_id: int) -> int:
    return REPLY_BASE + node_id


def command_words(data: bytes) -> str:
    """A command by its first byte, in the document's words."""
    try:
        return Command(data[0]).words if data else "empty frame"
    except ValueError:
        return f"unknown command 0x{data[0]:02X}"


class MyActuator(Protocol):
    """MyActuator RMD-X actuators, protocol V4.2."""

    name = "myactuator"
    Options = MyActuatorOptions
    node_ids = MOTOR_IDS
    has_following_error = False
    carries_torque_feed_forward = True
    models = MODELS
    drive = "hil.protocols.myactuator.drive:MyActuatorDrive"
    axis = "hil.protocols.myactuator.axis:MyActuatorAxis"

    @classmethod
    def initial_options(cls, setting: DriveSetting) -> dict:
        """The model (sized for the drive, else the X8-20) and the master's motion mode
        gains within §5.1's ranges."""
        return {"model": (setting.model or DEFAULT_MODEL),
                "kp": float(f"{min(setting.kp, 500.0):.4g}"),
                "kd": float(f"{min(setting.kd, 5.0):.4g}")}

    @classmethod
    def bus_frames(cls, node_id: int, cycle_hz: float, heartbeat_period: float,
                   options: MyActuatorOptions | None = None) -> list[FrameSpec]:
        """hil's master: a motion mode command a cycle, answered (§5); the single motor
        commands and replies on events (§2)."""
        return [FrameSpec(MIT_BASE + node_id, 8, cycle_hz, "motion mode control command"),
                FrameSpec(MIT_REPLY_BASE + node_id, 8, cycle_hz, "motion mode reply"),
                FrameSpec(command_id(node_id), 8, 0.0, "single motor command"),
                FrameSpec(reply_id(node_id), 8, 0.0, "single motor reply")]

    @classmethod
    def bus_wide_frames(cls, cycle_hz: float) -> list[FrameSpec]:
        return [FrameSpec(MULTI_MOTOR_ID, 8, 0.0, "multi-motor command"),
                FrameSpec(CANID_SETTING_ID, 8, 0.0, "CANID setting command")]

    @classmethod
    def description(cls) -> list[str]:
        """Every command of the document, as ``hil describe`` lists them."""
        return ["MyActuator RMD (protocol V4.2) single motor commands on 0x140+id, replies "
                "on 0x240+id: " + ", ".join(command.words for command in Command)]

    @classmethod
    def frame_source(cls, frame: Frame, drives: Mapping[int, object]) -> FrameSource | None:
        """Told by id (§1.1.2, §3, §4, §5); every command to a motor is answered, so each
        closes a cycle. 0x300 carries both the CANID command and its reply: a read's
        reply names the motor's reply id in bytes 6-7 (§4.3); a write's echo cannot be
        told from the write, and is taken for the master's."""
        if frame.extended:
            return None
        identifier, data = frame.identifier, frame.data
        node = identifier & 0x3F
        if identifier == MULTI_MOTOR_ID:
            return FrameSource(Sender.MASTER, None, "multi-motor " + command_words(data),
                               cycle=True)
        if identifier == CANID_SETTING_ID:
            answered = len(data) == 8 and data[2] == 1 and data[6] | data[7] << 8
            if answered and (data[6] | data[7] << 8) - REPLY_BASE in drives:
                return FrameSource(Sender.DRIVE, (data[6] | data[7] << 8) - REPLY_BASE,
                                   "CANID reply")
            return FrameSource(Sender.MASTER, None, "CANID setting command", cycle=True)
        if node not in drives or identifier - node not in _KINDS:
            return None
        sender, what = _KINDS[identifier - node]
        if not what:
            reply = " reply" if sender is Sender.DRIVE else ""
            what = (command_words(data) + reply if data and data[0] in _COMMANDS
                    else "single motor" + (reply or " command"))
        return FrameSource(sender, node, what, cycle=sender is Sender.MASTER)


_COMMANDS = frozenset(Command)
#: what each id base carries: (sender, words; "" for the command byte's)
_KINDS = {COMMAND_BASE: (Sender.MASTER, ""), REPLY_BASE: (Sender.DRIVE, ""),
          MIT_BASE: (Sender.MASTER, "motion mode control command"),
          MIT_REPLY_BASE: (Sender.DRIVE, "motion mode reply")}

__all__ = ["DEFAULT_MODEL", "MyActuator", "MyActuatorOptions", "command_id", "reply_id"]
