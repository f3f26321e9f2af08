"""Damiao DM-J motors on CAN FD, as the maker's FD firmware runs them.

What decides the motor's frames is its CAN_BR register (35, a rate code), as the DM4310's
firmware reads it (recovered in github.com/umeow0716/damiao_firmware,
board/src/board_mcan_config.c ``data_timing_for_selector``, ``nominal_timing_for_selector``;
board/src/board_mcan_hc32f448.c):

* codes 0-4: classic CAN at 125k, 200k, 250k, 500k and 1 Mbit/s (the MCAN's FDOE and BRSE
  cleared, ``board_mcan_init_classic``); the motor answers in classic frames.
* codes 5-11: CAN FD, 1 Mbit/s nominal and a data phase of 2, 2.5, 3.2, 4, 5, 8 or 10 Mbit/s
  (80 MHz over 40, 32, 25, 20, 16, 10 and 8 time quanta), FDOE and BRSE set
  (``board_mcan_init_fd``). python ``damiao-motor``'s CAN FD codes are 5-9 for 2M-5M
  (jia-xie/python-damiao-driver PR #9); OpenArm runs 5 Mbit/s (code 9; openarm #34).

In FD mode every answer, feedback and register answers alike, leaves as an FD frame with
the bit-rate switch and 8 data bytes, DLC 8 (``board_mcan_send_fd_payload``: the Tx
element's FDF and BRS, ``0x00300000``). What the motor takes does not depend on the
format: its receive path reads the identifier and 8 data bytes of the Rx element, never its
FDF or BRS (``board_mcan_receive_payload``), and an MCAN with FDOE set receives classic
frames and FD frames with or without BRS alike (ISO 11898-1:2015: BRS only decides the
sender's data phase). So a master's FD frames without BRS (LeRobot 0.4.4's: its
``can.Message(..., is_fd=True)`` sets no ``bitrate_switch``) reach the motor, and so do
classic ones; each is answered in FD with BRS. A write to CAN_BR takes effect at once
(``select_transport_format`` swaps the send function without restarting the MCAN), its own
answer included (hil's choice of order: the sources do not show which comes first).

A motor left classic on an FD bus: the recovered firmware's classic MCAN (FDOE cleared,
PXHD set) would refuse an FD frame with an error frame, but OpenArm's own motors were seen
to take it and answer in a classic frame (enactic/openarm_teleop #8: ``cansend can0
001##1.FFFFFFFFFFFFFFFD`` answered by a classic frame on an FD bus at 1M/5M). hil follows
what the hardware was seen to do: the motor takes the frame and answers classic, which a
master reading FD frames only misses (openarm_can's ``read_canfd_frame`` takes 72-byte
frames only, so its receive loop stops at a 16-byte classic one).

Each mismatch between a frame and the motor's CAN_BR (a classic frame to an FD motor, an FD
frame to a classic one) is logged once per motor and kind, naming the bus and node, with
what to do (:class:`FormatWatch`).
"""

from __future__ import annotations

import logging

from hil.can.frame import Frame

log = logging.getLogger(__name__)

#: CAN_BR's classic codes by bit rate (bit/s)
CLASSIC_CODES = {125_000: 0, 200_000: 1, 250_000: 2, 500_000: 3, 1_000_000: 4}
#: CAN_BR's CAN FD codes by data bit rate (bit/s); the nominal rate is 1 Mbit/s
FD_CODES = {2_000_000: 5, 2_500_000: 6, 3_200_000: 7, 4_000_000: 8, 5_000_000: 9,
            8_000_000: 10, 10_000_000: 11}
FD_NOMINAL = 1_000_000
#: the highest code the firmware has (its register check: 0-11)
MAX_RATE_CODE = max(FD_CODES.values())


def is_fd_code(code: float) -> bool:
    """Whether CAN_BR ``code`` runs the motor in CAN FD."""
    return int(code) > max(CLASSIC_CODES.values())


def rate_code(bitrate: int, fd: bool, data_bitrate: int | None) -> int:
    """The CAN_BR code of a bus' bit rates; ValueError naming the rates the motor takes."""
    if not fd:
        if bitrate not in CLASSIC_CODES:
            raise ValueError(f"a DM-J motor runs classic CAN at "
                             f"{', '.join(map(str, CLASSIC_CODES))} bit/s, not {bitrate}")
        return CLASSIC_CODES[bitrate]
    if bitrate != FD_NOMINAL or data_bitrate not in FD_CODES:
        raise ValueError(f"a DM-J motor runs CAN FD at {FD_NOMINAL} bit/s nominal and "
                         f"{', '.join(map(str, FD_CODES))} bit/s data, not {bitrate} and "
                         f"{data_bitrate}")
    return FD_CODES[data_bitrate]


class FormatWatch:
    """Reports, once per motor and kind, a frame whose format the motor's CAN_BR does not
    match (the module doc says what the motor does with it)."""

    def __init__(self, where: str):
        #: the motor, as the log names it: its bus and node
        self.where = where
        self._told: set[bool] = set()

    def note(self, frame: Frame, motor_fd: bool) -> None:
        """Log ``frame`` if its format is not the motor's (the first of its kind)."""
        if frame.fd == motor_fd or frame.fd in self._told:
            return
        self._told.add(frame.fd)
        if motor_fd:
            log.warning("%s: a classic CAN frame (%s) reached a motor whose CAN_BR is CAN FD: "
                        "it answers in CAN FD frames with BRS, which a classic-only master "
                        "does not receive (open python-can with fd=True, or a socket with "
                        "CAN_RAW_FD_FRAMES)", self.where, frame)
        else:
            log.warning("%s: a CAN FD frame (%s) reached a motor whose CAN_BR is classic: "
                        "it answers in classic frames (enactic/openarm_teleop #8), which a "
                        "master reading FD frames only misses; leave 'can_br' out of the "
                        "drive's options (it follows the bus: 9 at 5 Mbit/s data), as "
                        "Damiao's tool sets a motor for an FD bus", self.where, frame)
