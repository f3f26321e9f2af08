"""The endpoints a simulated ODrive backs over RxSdo/TxSdo (their names as firmware 0.6's
API reference and ODrive's CAN examples give them; their ids and types come from the user's
file), each bound to what the CAN commands of the same meaning read or do.

A write goes through the handler of the CANSimple command that sets the same thing, with
its checks: ``axis0.requested_state`` is Set_Axis_State (closed loop refused while errors
stand), ``controller.input_pos`` is Set_Input_Pos (in TRAP_TRAJ a planned move), and so on;
NaN and infinities are refused before (:mod:`.sdo`). Endpoints not listed here, and the
ones of ``axis1`` (hil simulates one axis per node), are answered as unknown ones are.
"""

from __future__ import annotations

from hil.protocols.odrive import BUS_VOLTAGE, TURN, Cmd
from hil.protocols.odrive.sdo import Backing


def backings(drive, handlers) -> dict[str, Backing]:
    """``drive`` (an ODriveDrive)'s endpoints by path; ``handlers`` are its CAN command
    handlers by command (each takes the command's decoded values)."""
    status = drive.core.status
    controller = "axis0.controller"

    def command(cmd: Cmd, values):
        return lambda v: handlers[cmd](values(v))

    return {
        **{f"hw_version_{k}": Backing(read=lambda v=v: v)
           for k, v in zip(("major", "minor", "variant"), drive.hardware_version)},
        **{f"fw_version_{k}": Backing(read=lambda v=v: v)
           for k, v in zip(("major", "minor", "revision"), drive.firmware_version)},
        "fw_version_unreleased": Backing(read=lambda: 0),
        # read by the odrive library as it connects (RuntimeDevice.attach_metadata): hil's
        # firmware has no build hash (0) and a valid OTP (its board identity)
        "commit_hash": Backing(read=lambda: 0),
        "otp_valid": Backing(read=lambda: True),
        "vbus_voltage": Backing(read=lambda: BUS_VOLTAGE),
        "clear_errors": Backing(call=lambda: handlers[Cmd.CLEAR_ERRORS](())),
        "axis0.current_state": Backing(read=lambda: int(drive.axis_state)),
        "axis0.requested_state": Backing(
            read=lambda: 0, write=command(Cmd.SET_AXIS_STATE, lambda v: (v,))),
        "axis0.active_errors": Backing(read=lambda: int(drive.active_errors)),
        "axis0.disarm_reason": Backing(read=lambda: int(drive.disarm_reason)),
        "axis0.pos_estimate": Backing(read=lambda: status().position / TURN),
        "axis0.vel_estimate": Backing(read=lambda: status().velocity / TURN),
        f"{controller}.config.control_mode": Backing(
            read=lambda: int(drive.control_mode),
            write=command(Cmd.SET_CONTROLLER_MODE, lambda v: (v, drive.input_mode))),
        f"{controller}.config.input_mode": Backing(
            read=lambda: int(drive.input_mode),
            write=command(Cmd.SET_CONTROLLER_MODE, lambda v: (drive.control_mode, v))),
        # the inputs as Set_Input_Pos / _Vel / _Torque with no feed-forwards
        f"{controller}.input_pos": Backing(write=command(Cmd.SET_INPUT_POS,
                                                         lambda v: (v, 0, 0))),
        f"{controller}.input_vel": Backing(write=command(Cmd.SET_INPUT_VEL,
                                                         lambda v: (v, 0.0))),
        f"{controller}.input_torque": Backing(write=command(Cmd.SET_INPUT_TORQUE,
                                                            lambda v: (v,))),
    }
