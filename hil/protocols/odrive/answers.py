"""What a simulated ODrive axis' Get_* messages and heartbeat carry (their layouts:
:data:`hil.protocols.odrive.LAYOUT`, ODrive's DBC), and how a replay reads the measured
ones. The drive (:mod:`.drive`) packs them; these tables say what goes in."""

from __future__ import annotations

from hil.protocols.odrive import BUS_VOLTAGE, TURN, Cmd


def _power(status) -> float:
    return status.torque * status.velocity


#: what each Get_* message (and the heartbeat) carries: (drive, core status) -> values
ANSWERS = {
    Cmd.GET_VERSION: lambda drive, status: (2, *drive.hardware_version,
                                            *drive.firmware_version, 0),
    Cmd.HEARTBEAT: lambda drive, status: (int(drive.active_errors), int(drive.axis_state), 0,
                                          int(drive.trajectory_done(status))),
    Cmd.GET_ERROR: lambda drive, status: (int(drive.active_errors), int(drive.disarm_reason)),
    Cmd.GET_ENCODER_ESTIMATES: lambda drive, status: (status.position / TURN,
                                                      status.velocity / TURN),
    Cmd.GET_IQ: lambda drive, status: (status.torque / drive.options.torque_constant,) * 2,
    Cmd.GET_TEMPERATURE: lambda drive, status: (35.0, 40.0),
    Cmd.GET_BUS_VOLTAGE_CURRENT: lambda drive, status: (BUS_VOLTAGE,
                                                        abs(_power(status)) / BUS_VOLTAGE),
    Cmd.GET_TORQUES: lambda drive, status: (status.torque, status.torque),
    Cmd.GET_POWERS: lambda drive, status: (abs(_power(status)), _power(status)),
}

#: how a replay reads the Get_* answers that carry measured values: (quantity, scale to SI)
#: per field (hil.drives.profile.Reading)
READINGS = {
    Cmd.GET_ENCODER_ESTIMATES: (("position", TURN), ("velocity", TURN)),
    Cmd.GET_TORQUES: (("torque", 1.0), ("torque", 1.0)),
    Cmd.GET_IQ: (("derived", 1.0), ("derived", 1.0)),
    Cmd.GET_BUS_VOLTAGE_CURRENT: ((None, 1.0), ("derived", 1.0)),
    Cmd.GET_POWERS: (("derived", 1.0), ("derived", 1.0)),
    Cmd.GET_TEMPERATURE: ((None, 1.0), (None, 1.0)),
}
