"""The private protocol's requests (CyberGear manual §4.1; the RS types 22-25 as
SampleProgram ``RS/Robstride01.cpp`` sends them) as a Robstride motor takes and answers
them: one function a type, each given the drive (lock held) and returning its answer.
"""

from __future__ import annotations

import struct
from typing import TYPE_CHECKING

from hil.can.frame import Frame
from hil.protocols.robstride import Robstride, framing_of
from hil.protocols.robstride import params as P
from hil.protocols.robstride.codec import (
    BROADCAST, Comm, PrivateId, RunMode, pack_feedback, private_id, unpack_motion,
)

if TYPE_CHECKING:
    from hil.protocols.robstride.drive import RobstrideDrive

#: the data bytes each request reads (§4.1's layouts; SampleProgram's byte 6 of types 23-25):
#: a shorter frame is refused and counted. The bytes a type does not read are not checked
#: (hil's choice: the makers' code sends 8 always, python-cybergear 0.1.2 asks the device id
#: with one byte, and a firmware that reads none of them answers it)
READS = {Comm.MOTION_CONTROL: 8, Comm.STOP: 1, Comm.SET_ZERO: 1, Comm.READ_PARAMETER: 2,
         Comm.WRITE_PARAMETER: 8, Comm.SAVE_PARAMETERS: 1, Comm.BAUD_RATE: 7,
         Comm.ACTIVE_REPORTING: 7, Comm.PROTOCOL: 7}
#: the baud-rate codes of types 22/23 (CyberGear §4.1.11): bit/s
BAUD_RATES = {1: 1_000_000, 2: 500_000, 3: 250_000, 4: 125_000}


def on_frame(drive: RobstrideDrive, frame: Frame) -> None:
    """An extended frame naming the motor: a request of its firmware's is handled and
    answered; the host a request names (bits 15-8; type 1 names none) is the one the motor
    answers (robstride 0.1.0 checks it)."""
    found = PrivateId.of(frame.identifier)
    handler = PRIVATE.get(found.comm)
    if handler is None or (found.comm > Comm.SAVE_PARAMETERS and drive.model.cybergear):
        return          # no request of the firmware's (an answer, a type it lacks)
    if len(frame.data) < READS.get(found.comm, 0):
        drive.malformed += 1           # too short for the bytes the type reads
        return
    with drive.lock:
        drive.heard()
        if found.comm != Comm.MOTION_CONTROL:    # type 1's bits 15-8 are its torque's
            drive.host = found.host
        drive.answer_with(handler(drive, found, bytes(frame.data)))


def feedback_frame(drive: RobstrideDrive) -> Frame:
    """Type 2 to the host (§4.1.3)."""
    identifier, data = pack_feedback(drive.reported(), drive.ranges, drive.host)
    return Frame(identifier, data, True)


def device_id_frame(drive: RobstrideDrive) -> Frame:
    """Type 0's answer (§4.1.1): the motor in bits 15-8, 0xFE, the 64-bit MCU id."""
    return Frame(private_id(Comm.GET_DEVICE_ID, drive.node_id, BROADCAST), drive.mcu_id(),
                 True)


def _get_device_id(drive: RobstrideDrive, found: PrivateId, data: bytes) -> Frame:
    return device_id_frame(drive)


def _motion(drive: RobstrideDrive, found: PrivateId, data: bytes) -> Frame:
    """Followed in operation control mode only (SampleProgram sets run_mode 0 before
    type 1; another mode's motor answers and moves on, hil's reading)."""
    if drive.run_mode == RunMode.OPERATION and drive.enabled:
        motion = unpack_motion(found.comm << 24 | found.data << 8, data, drive.ranges)
        drive.core.new_setpoint(position=motion.position + drive.zero,
                               velocity=motion.velocity, torque=motion.torque,
                               stiffness=motion.kp, damping=motion.kd)
    return feedback_frame(drive)


def _enable(drive: RobstrideDrive, found: PrivateId, data: bytes) -> Frame:
    drive.enable()
    return feedback_frame(drive)


def _stop(drive: RobstrideDrive, found: PrivateId, data: bytes) -> Frame:
    """§4.1.5: stop; byte 0 = 1 clears the faults."""
    drive.core.disable()
    if data[0] == 1:
        drive.clear_faults()
    return feedback_frame(drive)


def _set_zero(drive: RobstrideDrive, found: PrivateId, data: bytes) -> Frame:
    if data[0] == 1:
        drive.set_zero()
    return feedback_frame(drive)


def _set_can_id(drive: RobstrideDrive, found: PrivateId, data: bytes) -> Frame | None:
    """§4.1.7: the new id in bits 23-16, at once; answered with type 0 from it."""
    new = found.data >> 8
    if new not in Robstride.node_ids:
        return None                   # hil's choice: an id the table refuses is ignored
    drive.set_motor_id(new)
    return device_id_frame(drive)


def _read(drive: RobstrideDrive, found: PrivateId, data: bytes) -> Frame:
    """§4.1.8: index, 00 00, the value; an index it lacks answers status 1 in bits 23-16
    (the RS00 manual's measured answer)."""
    index = P.index_of(data)
    parameter = drive.table.get(index)
    value = parameter.pack(drive.read_value(index)) if parameter else bytes(4)
    status = 0 if parameter else 1
    return Frame(private_id(Comm.READ_PARAMETER, status << 8 | drive.node_id, drive.host),
                 P.parameter_frame(index, value), True)


def _write(drive: RobstrideDrive, found: PrivateId, data: bytes) -> Frame:
    """§4.1.9: into RAM (lost at a power cycle unless saved); answered with feedback.
    A read-only or unknown index changes nothing (hil's choice)."""
    parameter = drive.table.get(P.index_of(data))
    if parameter is not None and parameter.writable:
        drive.write_value(parameter.index, parameter.unpack(data))
    return feedback_frame(drive)


def _fault_feedback(drive: RobstrideDrive, found: PrivateId, data: bytes) -> Frame:
    """§4.1.10: the fault word (bytes 0-3) and the warnings (4-7), little-endian."""
    return Frame(private_id(Comm.FAULT_FEEDBACK, drive.node_id, drive.host),
                 struct.pack("<II", drive.fault_word(), 0), True)


def _save_or_baud(drive: RobstrideDrive, found: PrivateId, data: bytes) -> Frame:
    """Type 22: a CyberGear's baud rate in byte 0 (§4.1.11); the RS firmware's save
    (SampleProgram ``MotorDataSave``), answered with feedback (hil's choice)."""
    if drive.model.cybergear:
        return _set_baud(drive, data[0])
    drive.saved = dict(drive.values)
    return feedback_frame(drive)


def _baud(drive: RobstrideDrive, found: PrivateId, data: bytes) -> Frame:
    return _set_baud(drive, data[6])         # SampleProgram ``BaudRateChange``: byte 6


def _set_baud(drive: RobstrideDrive, code: int) -> Frame:
    if code in BAUD_RATES:
        drive.next_baud_code = code
    return device_id_frame(drive)          # §4.1.11: "reply motor broadcast frame"


def _active_reporting(drive: RobstrideDrive, found: PrivateId, data: bytes) -> Frame | None:
    """Byte 6: 1 on, 0 off (SampleProgram ``ProactiveEscalationSet``); the reports are
    type 2 frames (RS00 manual); the request itself is not answered (hil's choice)."""
    drive.reporting = data[6] == 1
    return None


def _protocol(drive: RobstrideDrive, found: PrivateId, data: bytes) -> Frame:
    """Byte 6: 0 private, 1 CANopen, 2 MIT, after a power cycle (SampleProgram README:
    "then power-cycle the motor"); answered with type 0 as MIT command 8 is."""
    if data[6] in (0, 1, 2):
        drive.next_framing = framing_of(data[6])
    return device_id_frame(drive)


#: the requests by type
PRIVATE = {Comm.GET_DEVICE_ID: _get_device_id, Comm.MOTION_CONTROL: _motion,
           Comm.ENABLE: _enable, Comm.STOP: _stop, Comm.SET_ZERO: _set_zero,
           Comm.SET_CAN_ID: _set_can_id, Comm.READ_PARAMETER: _read,
           Comm.WRITE_PARAMETER: _write, Comm.FAULT_FEEDBACK: _fault_feedback,
           Comm.SAVE_PARAMETERS: _save_or_baud, Comm.BAUD_RATE: _baud,
           Comm.ACTIVE_REPORTING: _active_reporting, Comm.PROTOCOL: _protocol}
