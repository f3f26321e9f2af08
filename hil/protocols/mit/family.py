"""What the MIT family's protocols (MIT, Damiao, CubeMars) share in their bus configs and on
their buses, written once: the options of a motor sold as models (its ranges from its
model, the master's gains), 11-bit ids in options, and how a bus monitor tells a command
to a motor's own id from an answer naming its motor in byte 0.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from typing import Any

from hil.can.frame import STANDARD_IDS, Frame
from hil.protocols.base import DriveSetting, FrameSource, Sender
from hil.protocols.mit.codec import MitRanges

#: kp and kd ranges of an MIT command on every Damiao and CubeMars model (Damiao's sample
#: code DM_CAN.py; TMotorCANControl's MIT_Params, motor-python's MOTOR_SPECS)
KP_MAX, KD_MAX = 500.0, 5.0


# --- options of a motor sold as models (Damiao's, CubeMars') --------------------------------

def parse_model(values: Mapping, find: Callable[[str], Any], default: Any) -> Any:
    """The ``model`` a drive's options name (``find`` raises KeyError naming the known
    ones), else ``default``; ValueError for an unknown one."""
    try:
        return find(str(values["model"])) if "model" in values else default
    except KeyError as exc:
        raise ValueError(exc.args[0]) from None


def parse_ranges(values: Mapping) -> dict[str, float]:
    """The mapping ranges the options set (``p_max``, ``v_max``, ``t_max``; the others
    stay the model's); ValueError naming one that is not positive."""
    ranges = {key: float(values[key]) for key in ("p_max", "v_max", "t_max") if key in values}
    for key, value in ranges.items():
        if not value > 0:
            raise ValueError(f"'{key}' must be > 0")
    return ranges


def parse_gains(values: Mapping) -> tuple[float, float]:
    """The master's ``kp`` and ``kd`` (0: none), within the command's ranges."""
    kp, kd = float(values.get("kp", 0.0)), float(values.get("kd", 0.0))
    if not (0 <= kp <= KP_MAX and 0 <= kd <= KD_MAX):
        raise ValueError(f"'kp' must be in [0, {KP_MAX:g}] and 'kd' in [0, {KD_MAX:g}]")
    return kp, kd


def parse_standard_id(values: Mapping, key: str, default: int | None) -> int | None:
    """An id the options give (``reply_id``, ``master_id``), which the family's motors
    send and take as 11-bit ids only; ValueError for one that is not."""
    value = values.get(key, default)
    if value is None:
        return None
    if not 0 <= int(value) <= STANDARD_IDS:
        raise ValueError(f"'{key}' {int(value)} is not an 11-bit CAN id")
    return int(value)


def model_ranges(found, p_max: float | None, v_max: float | None, t_max: float | None
                 ) -> MitRanges:
    """The MIT mapping a model's motor starts with: the options' ranges where they give one,
    else the model's; the gains' ranges every model shares."""
    return MitRanges(p_max or found.p_max, v_max or found.v_max, KP_MAX, KD_MAX,
                     t_max or found.t_max)


def model_figures(found) -> dict[str, float | bool]:
    """A model's published output figures a drive of the bus config takes by default: peak
    and rated torque, no-load speed; no holding brake (neither maker's manuals list one)."""
    return {"peak_torque": found.peak_torque, "rated_torque": found.rated_torque,
            "max_velocity": found.no_load_speed, "holding_brake": False}


def initial_model_options(setting: DriveSetting, models: Mapping[str, Any], default: str
                          ) -> dict:
    """What ``hil init`` writes for a drive of a family sold as models: the model (sized for
    the drive, else ``default``) with its ranges, and the master's gains within the
    command's ranges."""
    found = models[setting.model or default]
    return {"model": found.name, "p_max": found.p_max, "v_max": found.v_max,
            "t_max": found.t_max, "kp": float(f"{min(setting.kp, KP_MAX):.4g}"),
            "kd": float(f"{min(setting.kd, KD_MAX):.4g}")}


# --- the bus -----------------------------------------------------------------------------

def told_by_motor_id(frame: Frame, drives: Mapping[int, object], reply_ids: set[int],
                     answer: str) -> FrameSource | None:
    """The mini-cheetah firmware's frames as a bus monitor tells them: a command goes to the
    motor's own (11-bit) id; its answer to a reply id the motors share, naming the motor in
    byte 0 (``answer``: what the family calls it)."""
    identifier = frame.identifier
    if identifier in drives:
        return FrameSource(Sender.MASTER, identifier, "command", cycle=True)
    data = frame.data
    if identifier in reply_ids and data and data[0] in drives:
        return FrameSource(Sender.DRIVE, data[0], answer)
    return None
