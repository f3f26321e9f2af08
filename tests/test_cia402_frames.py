"""CiA 402's frames as its protocol declares them (issue 66 items 1 and 2): the bus-wide ones
(NMT, SYNC) and the SYNC that ends a cycle come from the protocol, and a frame is told by
CiA 301's predefined connection set (7.3.5), whose identifiers are 11-bit ones."""

from __future__ import annotations

from hil.can.frame import Frame, FrameSpec
from hil.protocols.base import Sender
from hil.protocols.cia402 import Cia402


def test_the_bus_wide_frames_are_the_masters_nmt_and_its_sync_every_cycle():
    assert Cia402.bus_wide_frames(250.0) == [FrameSpec(0x000, 2, 0.0, "NMT"),
                                            FrameSpec(0x080, 0, 250.0, "SYNC")]
    assert Cia402.cycle_end_frames == (Frame(0x080),)


def test_a_29_bit_frame_is_no_cia402_drives_whatever_its_number():
    drives = {1: None}
    tpdo = Cia402.frame_source(Frame(0x181, bytes(6)), drives)
    assert (tpdo.sender, tpdo.node_id, tpdo.what) == (Sender.DRIVE, 1, "TPDO1")
    assert Cia402.frame_source(Frame(0x181, bytes(6), extended=True), drives) is None
    assert Cia402.frame_source(Frame(0x000, bytes([1, 1]), extended=True), drives) is None
    assert not Cia402.source_reads_data(Frame(0x000, extended=True), drives)
