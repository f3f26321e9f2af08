"""SDO block transfers and the server-side SDO timeout (CiA 301 7.2.4.3.9-16, and
CANopenNode's CO_SDOserver.c for the protocol switch and the 0x05040000 timeout), against
python canopen's client and raw frames."""

from __future__ import annotations

import struct

import pytest

from test_cia402_conformance import FrameTap, pre_operational, raw, wait_until

SDO_REQUEST, SDO_ANSWER = 0x601, 0x581


def _answers(tap: FrameTap) -> list[bytes]:
    return [bytes(msg.data) for msg in tap.of(SDO_ANSWER)]


@pytest.mark.wire("a block's burst of frames")
def test_a_block_upload_gives_the_device_name_with_its_crc(canopen_bench):
    node = pre_operational(canopen_bench)
    expected = node.sdo.upload(0x1008, 0)                 # segmented
    assert len(expected) > 4
    with FrameTap(canopen_bench) as tap:
        with node.sdo.open(0x1008, 0, "rb", block_transfer=True) as stream:
            assert stream.read() == expected
        assert wait_until(lambda: len(_answers(tap)) >= 3)
    initiate = _answers(tap)[0]
    assert initiate[0] == 0xC6                           # block upload, size and CRC
    assert struct.unpack_from("<I", initiate, 4)[0] == len(expected)


def test_a_block_upload_at_or_under_the_switch_threshold_is_a_normal_upload(canopen_bench):
    pre_operational(canopen_bench)
    with FrameTap(canopen_bench) as tap:                  # 0x6041 (2 bytes), pst 4
        raw(canopen_bench, SDO_REQUEST, bytes([0xA4, 0x41, 0x60, 0x00, 16, 4, 0, 0]))
        assert wait_until(lambda: _answers(tap))
    assert _answers(tap)[0][0] == 0x4B                   # expedited upload of 2 bytes
    with FrameTap(canopen_bench) as tap:                  # pst 0: no switch, a block upload
        raw(canopen_bench, SDO_REQUEST, bytes([0xA4, 0x41, 0x60, 0x00, 16, 0, 0, 0]))
        assert wait_until(lambda: _answers(tap))
        raw(canopen_bench, SDO_REQUEST, bytes([0xA1, 0, 0, 0, 0, 0, 0, 0]))  # client aborts
    assert _answers(tap)[0][0] == 0xC6


@pytest.mark.wire("a block's burst of frames")
def test_a_block_download_writes_the_object(canopen_bench):
    node = pre_operational(canopen_bench)
    with node.sdo.open(0x6081, 0, "wb", size=4, block_transfer=True) as stream:
        stream.write(struct.pack("<I", 123456))
    assert node.sdo[0x6081].raw == 123456


def test_a_block_download_with_a_wrong_crc_is_aborted(canopen_bench):
    node = pre_operational(canopen_bench)
    before = node.sdo[0x6081].raw
    with FrameTap(canopen_bench) as tap:
        raw(canopen_bench, SDO_REQUEST, bytes([0xC6, 0x81, 0x60, 0x00, 4, 0, 0, 0]))  # size, CRC
        assert wait_until(lambda: _answers(tap))
        raw(canopen_bench, SDO_REQUEST, bytes([0x81]) + struct.pack("<I", 99) + bytes(3))
        assert wait_until(lambda: len(_answers(tap)) >= 2)
        raw(canopen_bench, SDO_REQUEST, bytes([0xC1 | 3 << 2, 0x12, 0x34, 0, 0, 0, 0, 0]))
        assert wait_until(lambda: len(_answers(tap)) >= 3)
    initiate, ack, end = _answers(tap)[:3]
    assert initiate[0] == 0xA4 and initiate[4] == 127      # server's block size
    assert ack[:2] == bytes([0xA2, 1])                     # segment 1 taken
    assert end[0] == 0x80 and struct.unpack_from("<I", end, 4)[0] == 0x05040004
    assert node.sdo[0x6081].raw == before


def test_a_stalled_segmented_upload_is_aborted_by_the_server(canopen_bench):
    pre_operational(canopen_bench)
    with FrameTap(canopen_bench) as tap:
        raw(canopen_bench, SDO_REQUEST, bytes([0x40, 0x08, 0x10, 0x00, 0, 0, 0, 0]))  # 0x1008
        assert wait_until(lambda: _answers(tap))
        assert _answers(tap)[0][0] == 0x41                 # segmented: the client is due
        # the client goes silent: the server gives up after its timeout (1 s)
        assert wait_until(lambda: len(_answers(tap)) >= 2, timeout=5.0)
    aborted = _answers(tap)[1]
    assert aborted[0] == 0x80 and struct.unpack_from("<HBI", aborted, 1) == (0x1008, 0,
                                                                            0x05040000)
    with FrameTap(canopen_bench) as tap:                  # the transfer is over
        raw(canopen_bench, SDO_REQUEST, bytes([0x60, 0, 0, 0, 0, 0, 0, 0]))
        assert wait_until(lambda: _answers(tap))
    assert struct.unpack_from("<I", _answers(tap)[0], 4)[0] == 0x05040001


@pytest.mark.parametrize("initiate", [0xC6, 0xC4], ids=["size indicated", "size not indicated"])
def test_a_block_download_past_its_size_is_aborted_data_too_long(canopen_bench, initiate):
    """CiA 301 0x06070012 (length too high), where CANopenNode's CO_SDOserver.c aborts with
    CO_SDO_AB_DATA_LONG: a segment that comes when the 4 bytes of 0x6081 (the indicated
    size, else the object's) are taken already; nothing is written."""
    node = pre_operational(canopen_bench)
    before = node.sdo[0x6081].raw
    with FrameTap(canopen_bench) as tap:
        raw(canopen_bench, SDO_REQUEST, bytes([initiate, 0x81, 0x60, 0x00, 4, 0, 0, 0]))
        assert wait_until(lambda: _answers(tap))
        for seq in (1, 2, 3):                            # no last-segment bit: 21 bytes
            raw(canopen_bench, SDO_REQUEST, bytes([seq]) + bytes(7))
        assert wait_until(lambda: len(_answers(tap)) >= 2)
    abort = _answers(tap)[1]
    assert abort[0] == 0x80 and struct.unpack_from("<I", abort, 4)[0] == 0x06070012
    assert node.sdo[0x6081].raw == before
