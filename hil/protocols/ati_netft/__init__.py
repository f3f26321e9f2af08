"""ATI Industrial Automation's Net F/T on CAN, as its manual (9620-05-NET FT, section 15,
"CAN Bus Interface") describes it: the sensor answers requests, it never streams.

The master sends one byte to the base identifier (set by the Net F/T's DIP switches):

=======  =====================================================================
0x01     request long data: four frames, little-endian int32 pairs
         base+1 Fx, Tx; base+2 Fy, Ty; base+3 Fz, Tz; base+4 status, sample number
0x02     request short data (manual table 15.2): two frames, little-endian int16s
         base+5 Fx, Tx, Fy, Ty; base+6 Fz, Tz, status, sample number
0x04     bias (table 15.3): the readings are zeroed at the present load
0x08     clear the threshold latch (no threshold is modelled: nothing to clear)
=======  =====================================================================

A request takes the latest sample ("each request copies the current data into a buffer and
sends it"). The values are counts: force x counts per force, torque x counts per torque,
the calibration's figures, which the Net F/T gives over Ethernet, not CAN: the master
configures them, as the bus config does here. Short data's 16-bit counts are the long
counts divided by the calibration's scale factors ("further scaling for 16-bit counts";
hil's reading: one divisor for forces, one for torques). The long layout comes from the
manual's "four messages" and an open client of it (netft_node's update_data); the manual's
long-data table was not available to hil.
"""

from __future__ import annotations

import struct

from hil.can.frame import Frame, FrameSpec
from hil.protocols.imu import raw

LONG, SHORT, BIAS, CLEAR_THRESHOLD = 0x01, 0x02, 0x04, 0x08
COMMANDS = {LONG: "request long data", SHORT: "request short data", BIAS: "bias",
            CLEAR_THRESHOLD: "clear threshold latch"}
#: the answers' identifiers after the base
LONG_ANSWERS = (1, 2, 3, 4)
SHORT_ANSWERS = (5, 6)
#: the highest base identifier: its last answer, base + 6, is still an 11-bit identifier
MAX_BASE_ID = 0x7FF - 6
#: a healthy status word (hil models no fault of the sensor's own)
STATUS_OK = 0


def long_answer(base_id: int, force_counts: list[int], torque_counts: list[int],
                status: int, sample: int) -> list[Frame]:
    """The four frames of a long-data answer."""
    fx, fy, fz = force_counts
    tx, ty, tz = torque_counts
    return [Frame(base_id + 1, struct.pack("<ii", fx, tx)),
            Frame(base_id + 2, struct.pack("<ii", fy, ty)),
            Frame(base_id + 3, struct.pack("<ii", fz, tz)),
            Frame(base_id + 4, struct.pack("<iI", status, sample & 0xFFFFFFFF))]


def short_answer(base_id: int, force_counts: list[int], torque_counts: list[int],
                 status: int, sample: int) -> list[Frame]:
    """The two frames of a short-data answer (16-bit counts)."""
    fx, fy, fz = force_counts
    tx, ty, tz = torque_counts
    return [Frame(base_id + 5, struct.pack("<4h", fx, tx, fy, ty)),
            Frame(base_id + 6, struct.pack("<3hH", fz, tz, status, sample & 0xFFFF))]


def counts(values, counts_per_unit: float, bits: int) -> list[int]:
    """Forces (N) or torques (N·m) as a field's counts, clipped at its range."""
    return raw([float(v) for v in values], 1.0 / counts_per_unit, bits)


def frame_specs(base_id: int, poll_hz: float, what: str) -> list[FrameSpec]:
    """The sensor's frames on the bus: its master's long-data requests at ``poll_hz`` and
    their answers; the short answers (only on a request of another master: rate 0)."""
    return [FrameSpec(base_id, 1, poll_hz, f"{what} request")] + [
        FrameSpec(base_id + n, 8, poll_hz if n < 5 else 0.0,
                  f"{what} {'long' if n < 5 else 'short'} data {n}")
        for n in LONG_ANSWERS + SHORT_ANSWERS]
