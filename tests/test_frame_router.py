"""hil's frame value (hil.can.frame), its router (hil.can.router), its wire checks and its
cost on a bus (hil.can.frames): classic CAN and CAN FD (ISO 11898-1:2015)."""

from __future__ import annotations

import logging
import queue
import re
import time
import uuid

import can
import pytest

from hil.can.frame import FD_LENGTHS, Frame, FrameSpec
from hil.can.frames import BusLoad, bus_load
from hil.can.messages import message_of
from hil.can.router import FrameRouter, start_router
from hil.can.zenoh_wire import decode_frames, encode_frames

#: what CAN FD carries at most: a 64-byte frame, extended id, data phase at the data bit rate
FD_FRAME = Frame(0x12345678, bytes(range(64)), extended=True, fd=True, bitrate_switch=True)


@pytest.fixture
def router():
    """A router whose frames the test hands it (``on_frames``), on a bus of its own."""
    bus = can.Bus(interface="hil-virtual", channel=f"router-{uuid.uuid4().hex[:8]}")
    yield FrameRouter(bus)
    bus.shutdown()


def _hear(router: FrameRouter, identifier: int, extended: bool = False, remote: bool = False,
          mask: int | None = None) -> list[Frame]:
    heard: list[Frame] = []
    router.subscribe(identifier, heard.append, extended, remote, mask)
    return heard


def test_a_subscriber_hears_its_identifiers_frames_until_it_unsubscribes(router):
    heard = _hear(router, 0x181)
    other = _hear(router, 0x181)
    router.on_frames([Frame(0x181, b"\x01"), Frame(0x182, b"\x02")])
    router.unsubscribe(0x181, heard.append)
    router.on_frames([Frame(0x181, b"\x03")])
    assert heard == [Frame(0x181, b"\x01")]
    assert other == [Frame(0x181, b"\x01"), Frame(0x181, b"\x03")]
    assert router.handlers(0x181) == (other.append,)
    router.unsubscribe(0x181, other.append)
    router.unsubscribe(0x181, other.append)         # not subscribed: nothing happens
    assert router.handlers(0x181) == ()


def test_a_standard_and_an_extended_frame_of_one_number_are_kept_apart(router):
    """ISO 11898-1: the IDE bit makes an 11-bit and a 29-bit identifier of one value two
    frames (a CubeMars servo listens on extended ids below 0x800)."""
    standard, extended = _hear(router, 0x101), _hear(router, 0x101, extended=True)
    router.on_frames([Frame(0x101, b"\x01"), Frame(0x101, b"\x02", extended=True)])
    assert standard == [Frame(0x101, b"\x01")]
    assert extended == [Frame(0x101, b"\x02", extended=True)]
    assert router.handlers(0x101, extended=True) == (extended.append,)


def test_remote_frames_go_to_remote_subscribers_and_data_frames_to_data_ones(router):
    data, asked = _hear(router, 0x209), _hear(router, 0x209, remote=True)
    request, answer = Frame(0x209, bytes(8), remote=True), Frame(0x209, b"\x01")
    router.on_frames([request, answer])
    assert asked == [request] and data == [answer]


def test_a_mask_subscription_hears_every_identifier_whose_masked_bits_match(router):
    # a CANopen function code: an 11-bit id's top 4 bits, the node id the 7 below them
    # (CiA 301, the pre-defined connection set)
    heard = _hear(router, 0x185, mask=0x780)          # bits outside the mask do not count
    router.on_frames([Frame(0x181, b"\x01"), Frame(0x1FF, b"\x02"), Frame(0x201, b"\x03"),
                      Frame(0x181, b"\x04", extended=True), Frame(0x181, remote=True)])
    assert heard == [Frame(0x181, b"\x01"), Frame(0x1FF, b"\x02")]
    router.unsubscribe(0x185, heard.append, mask=0x780)
    router.on_frames([Frame(0x181, b"\x05")])
    assert len(heard) == 2


def test_subscribers_of_one_mask_each_hear_their_own_frames_and_a_shared_one_in_order(router):
    # as Robstride motors on a bus (29-bit ids, the motor in bits 7-0) and moteus'
    # broadcast id: a frame goes to the subscribers of its masked bits, in the order they
    # subscribed; another mask's subscriber of the same frame hears it too
    motors = {node: _hear(router, node, extended=True, mask=0xFF) for node in range(1, 9)}
    broadcast = [_hear(router, 0x7F, extended=True, mask=0xFF) for _ in range(2)]
    heard: list[str] = []
    router.subscribe(0x7F, lambda frame: heard.append("first"), True, mask=0xFF)
    router.subscribe(0x7F, lambda frame: heard.append("second"), True, mask=0xFF)
    wide = _hear(router, 0x1200_0000, extended=True, mask=0x1F00_0000)
    frames = [Frame(0x1200_FD03, b"\x01", extended=True), Frame(0x0300_FD07, extended=True),
              Frame(0x0200_FD7F, extended=True), Frame(0x03, b"\x02")]
    router.on_frames(frames)
    assert {node: len(each) for node, each in motors.items()} == \
        {1: 0, 2: 0, 3: 1, 4: 0, 5: 0, 6: 0, 7: 1, 8: 0}
    assert broadcast[0] == broadcast[1] == [frames[2]] and heard == ["first", "second"]
    assert wide == [frames[0]]
    router.unsubscribe(3, motors[3].append, extended=True, mask=0xFF)
    router.unsubscribe(0x1200_0000, wide.append, extended=True, mask=0x1F00_0000)
    router.on_frames(frames)
    assert len(motors[3]) == 1 and len(motors[7]) == 2 and len(wide) == 1


def test_a_remote_mask_subscription_hears_remote_frames_only(router):
    asked = _hear(router, 0x600, remote=True, mask=0x780)
    request = Frame(0x601, bytes(8), remote=True)
    router.on_frames([Frame(0x601, b"\x01"), request])
    assert asked == [request]


def test_a_raising_handler_is_counted_logged_once_per_identifier_the_others_still_called(
        router, caplog):
    def broken(frame):
        raise ValueError("wrong length")

    router.subscribe(0x181, broken)
    router.subscribe(0x182, broken)
    heard = _hear(router, 0x181)                     # after the failing one, on the same id
    masked = _hear(router, 0x180, mask=0x780)
    router.subscribe(0x180, broken, mask=0x780)      # a masked one fails too
    with caplog.at_level(logging.WARNING, logger="hil.can.router"):
        router.on_frames([Frame(0x181, b"\x01")] * 3 + [Frame(0x182, b"\x02")])
    assert len(heard) == 3 and len(masked) == 4
    assert router.refused == 8                       # 3 + 1 by id, 4 by mask
    lines = [record.getMessage() for record in caplog.records]
    assert len(lines) == 2 and "Traceback" not in caplog.text      # one line per id
    assert "0x181" in lines[0] and "broken" in lines[0] and "wrong length" in lines[0]
    assert "0x182" in lines[1]


def test_a_refusing_identifier_is_logged_again_every_log_every_frames(router, caplog):
    def broken(frame):
        raise ValueError("wrong length")

    router.subscribe(0x181, broken)
    router.LOG_EVERY = 2
    with caplog.at_level(logging.WARNING, logger="hil.can.router"):
        router.on_frames([Frame(0x181, b"\x01")] * 4)
    first, third = (record.getMessage() for record in caplog.records)
    assert "(1 from this id so far)" in first and "(3 from this id so far)" in third


class RefusingBus(can.BusABC):
    """A bus whose transmit queue is always full (python-can raises CanOperationError)."""

    def __init__(self):
        super().__init__(channel="refusing")
        self.sends = 0

    def send(self, msg: can.Message, timeout: float | None = None) -> None:
        self.sends += 1
        raise can.CanOperationError("transmit buffer full")

    def _recv_internal(self, timeout):
        return None, False


def test_a_keep_sending_router_counts_the_frames_its_bus_refuses_and_logs_the_first(caplog):
    bus = RefusingBus()
    router = FrameRouter(bus, keep_sending=True)
    with caplog.at_level(logging.WARNING, logger="hil.can.router"):
        router.send_frames([Frame(0x181, b"\x01"), Frame(0x281, b"\x02")])
        router.send(Frame(0x381, b"\x03"))
    assert router.lost_frames == 3 and bus.sends == 2     # the batch stopped at its first
    (record,) = caplog.records
    assert "0x181" in record.getMessage() and "transmit buffer full" in record.getMessage()
    bus.shutdown()


def test_a_router_that_does_not_keep_sending_raises_what_its_bus_refuses():
    bus = RefusingBus()
    router = FrameRouter(bus)
    with pytest.raises(can.CanOperationError, match="transmit buffer full"):
        router.send(Frame(0x181, b"\x01"))
    assert router.lost_frames == 0
    bus.shutdown()


@pytest.fixture(params=["hil-virtual", "zenoh"])
def opener(request):
    """Opens buses on one new channel of the parameter's interface: the first the sender's
    (zenoh: listening on loopback, the others' session connecting to it, as bus_pair has
    them), ``reader=True`` python-can's own bus for the interface; ``fd`` python-can's
    option (hil.can.fd_option)."""
    opened: list[can.BusABC] = []
    zenoh = request.param == "zenoh"
    endpoint = request.getfixturevalue("endpoint") if zenoh else None
    channel = f"test/{time.monotonic_ns()}" if zenoh else f"fd-{uuid.uuid4().hex[:8]}"

    def open_bus(reader: bool = False, fd: bool = True) -> can.BusABC:
        if not zenoh:
            bus = can.Bus(interface="virtual" if reader else "hil-virtual", channel=channel,
                          fd=fd)
        else:
            side = {"connect": [endpoint]} if opened else {"listen": [endpoint]}
            bus = can.Bus(interface="zenoh", channel=channel, fd=fd, **side)
        opened.append(bus)
        return bus

    yield open_bus
    for bus in opened:
        bus.shutdown()


def test_a_bus_opened_without_fd_refuses_to_send_an_fd_frame_and_hears_none(opener):
    """As a SocketCAN raw socket without CAN_RAW_FD_FRAMES (Linux's
    Documentation/networking/can.rst): EINVAL on send, FD frames not passed to it."""
    fd_end, classical_end = opener(), opener(fd=False)
    assert (fd_end.protocol, classical_end.protocol) == (can.CanProtocol.CAN_FD,
                                                         can.CanProtocol.CAN_20)
    fd_msg = message_of(FD_FRAME)
    with pytest.raises(can.CanOperationError, match="fd=True"):
        classical_end.send(fd_msg)
    fd_end.send(fd_msg)
    fd_end.send(can.Message(arbitration_id=0x123, data=b"\x01"))     # a classical frame
    heard = classical_end.recv(5)
    assert heard is not None and (heard.arbitration_id, heard.is_fd) == (0x123, False)
    assert classical_end.recv(0.2) is None


def test_a_64_byte_fd_extended_frame_with_bit_rate_switch_crosses_the_bus_bit_for_bit(
        opener):
    sender, receiver = start_router(opener()), start_router(opener())
    heard: queue.Queue[Frame] = queue.Queue()
    receiver.subscribe(FD_FRAME.identifier, heard.put, extended=True)
    try:
        sender.send(FD_FRAME)                            # router to router
        assert heard.get(timeout=5)._replace(timestamp=0.0) == FD_FRAME
        reader = opener(reader=True)
        sender.send(FD_FRAME)                            # and to python-can's bus
        assert heard.get(timeout=5)._replace(timestamp=0.0) == FD_FRAME
        msg = reader.recv(5)
        assert msg is not None
        assert (msg.arbitration_id, msg.is_extended_id, msg.is_fd, msg.bitrate_switch,
                msg.dlc, bytes(msg.data), msg.is_remote_frame) == (
            FD_FRAME.identifier, True, True, True, 64, FD_FRAME.data, False)
    finally:
        sender.stop()
        receiver.stop()


@pytest.mark.parametrize("frame, problem", [
    (Frame(0x7FF, bytes(8)), None),
    (Frame(0x800), "identifier 0x800 does not fit 11 bits"),
    (Frame(0x800, extended=True), None),
    (Frame(0x1FFFFFFF, extended=True), None),
    (Frame(0x20000000, extended=True), "identifier 0x20000000 does not fit 29 bits"),
    (Frame(0x181, bytes(9)), "a classic CAN frame carries 0..8 data bytes, not 9"),
    (Frame(0x181, bytes(8), remote=True), None),
    (Frame(0x181, bytes(13), fd=True), f"a CAN FD frame carries one of {FD_LENGTHS} data "
                                       "bytes, not 13"),
    (Frame(0x181, bytes(65), fd=True), "not 65"),
    (Frame(0x181, bytes(8), fd=True, remote=True), "CAN FD has no remote frames"),
    (Frame(0x181, b"\x01", bitrate_switch=True), "only a CAN FD frame switches its bit rate"),
    (FD_FRAME, None)], ids=str)
def test_a_frame_names_what_makes_it_one_no_controller_sends(frame, problem):
    """ISO 11898-1:2015: identifiers of 11 or 29 bits, 0-8 data bytes in classic CAN, a CAN
    FD frame's lengths those of its DLC codes (table 5), no remote frame in CAN FD (the RRS
    bit is always dominant), BRS only in a CAN FD frame."""
    if problem is None:
        assert frame.problem() is None
    else:
        assert problem in frame.problem()


@pytest.mark.parametrize("length", FD_LENGTHS)
def test_every_length_a_can_fd_dlc_says_is_a_frame(length):
    assert Frame(0x181, bytes(length), fd=True, bitrate_switch=True).problem() is None


def _with(frame: Frame) -> bytes:
    """A section of a good frame, then ``frame``: what a decoder must find in frame 2."""
    return encode_frames("x", 1, 1, 0.0, [Frame(0x100, b"\x01"), frame])


def _flagged(flags: int) -> bytes:
    """:func:`_with` a 1-byte frame of these wire flags (encode_frames writes only those a
    Frame has: a classic frame's bit-rate switch it leaves out)."""
    payload = _with(Frame(0x101, b"\x01", extended=True))
    return payload[:-3] + bytes([flags]) + payload[-2:]     # flags, length, data


@pytest.mark.parametrize("payload, reason", [
    (_with(Frame(0x101, bytes(9), fd=True)), "a CAN FD frame of 9 data bytes"),
    (_with(Frame(0x101, bytes(65), fd=True)), "a CAN FD frame of 65 data bytes"),
    (_with(Frame(0x101, bytes(64), fd=True, remote=True)), "a CAN FD remote frame"),
    (_flagged(0x10), "a bit-rate switch without CAN FD"),
    (_with(Frame(0x101, bytes(12), extended=True)), "DLC 12 in a classic CAN frame"),
    (_with(FD_FRAME)[:-10], "DLC 64 does not match 54 data bytes"),
    (_flagged(0x21), "unknown flags 0x21")])
def test_the_zenoh_wire_refuses_each_malformed_fd_frame_naming_it(payload, reason):
    with pytest.raises(ValueError, match=re.escape(f"channel 'x': frame 2 of 2: {reason}")):
        decode_frames(payload)


def test_the_zenoh_wire_names_a_classic_standard_frame_of_more_than_8_bytes():
    with pytest.raises(ValueError, match=re.escape("frame 2 of 2: DLC 12 in a classic CAN")):
        decode_frames(_with(Frame(0x101, bytes(12))))


def test_classic_bus_load_is_what_it_was_for_a_known_set_of_frames():
    """Issue 66 changed bus_load's input to FrameSpecs, not its figures. Per frame
    (frame_bits: 47 + 8n bits, worst-case stuffing floor((34 + 8n - 1) / 4); 29-bit: 67 + 8n
    and floor((54 + 8n - 1) / 4)): 6 bytes 95/115, 8 bytes 111/135, 0 bytes 47/55, 1 byte
    55/65, 29-bit 8 bytes 131/160, 29-bit 0 bytes 67/80. Nominal: 500 x (95 + 111 + 47)
    + 10 x 55 + 100 x 131 + 10 x 67 = 140820; worst: 500 x (115 + 135 + 55) + 10 x 65
    + 100 x 160 + 10 x 80 = 169950 (the figures of hil before issue 66, computed by its
    bus_load over (payload, rate[, extended]) tuples)."""
    specs = [FrameSpec(0x181, 6, 500, "TPDO1"), FrameSpec(0x201, 8, 500, "RPDO1"),
             FrameSpec(0x080, 0, 500, "SYNC"), FrameSpec(0x701, 1, 10, "heartbeat"),
             FrameSpec(0x1ABCDE, 8, 100, extended=True),
             FrameSpec(0x1ABCDF, 0, 10, "request", extended=True)]
    assert bus_load(1_000_000, specs) == BusLoad(1620.0, 140820.0, 169950.0, 1_000_000)
    # a data bit rate changes no classic frame
    assert bus_load(1_000_000, specs, data_bitrate=4_000_000) == bus_load(1_000_000, specs)


def test_a_64_byte_standard_fd_frame_costs_what_iso_11898_1_field_lengths_add_up_to():
    """Worked from hil/can/frames.py's field lengths (ISO 11898-1:2015, 10.4), a 64-byte
    CAN FD data frame with an 11-bit identifier:

    * nominal phase: SOF, 11-bit id, RRS, IDE, FDF, res, BRS = 17 bits; CRC delimiter, ACK
      slot and delimiter, EOF (7), intermission (3) = 13 bits;
    * data phase: ESI 1 + DLC 4 + 64 x 8 data + stuff count 4 + CRC-21 (above 16 bytes)
      = 542 bits;
    * fixed stuff bits, in every frame: one before the stuff count and after every 4 bits
      of it and the CRC, 1 + (4 + 21) // 4 = 7;
    * without dynamic stuffing: 17 + 13 + 542 + 7 = 579 bit times;
    * dynamic stuffing at worst, one per 4 bits after the first: (17 - 1) // 4 = 4 in the
      nominal phase and (1 + 4 + 512) // 4 = 129 in the data phase: 579 + 4 + 129 = 712.

    With the data phase at 4x the nominal bit rate (BRS, 500 kbit/s and 2 Mbit/s), each
    data-phase bit costs 1/4 of a nominal bit time: 30 + (542 + 7) / 4 = 167.25 without
    dynamic stuffing, and 167.25 + 4 + 129 / 4 = 203.5 at worst."""
    plain = FrameSpec(0x100, 64, 1.0, fd=True)
    switched = FrameSpec(0x100, 64, 1.0, fd=True, bitrate_switch=True)
    assert bus_load(500_000, [plain]) == BusLoad(1.0, 579.0, 712.0, 500_000)
    assert bus_load(500_000, [switched], data_bitrate=2_000_000) == BusLoad(
        1.0, 167.25, 203.5, 500_000)


@pytest.mark.parametrize("length", [8, 64])
@pytest.mark.parametrize("extended", [False, True])
def test_an_fd_frame_switching_to_a_4x_data_bit_rate_costs_fewer_nominal_bit_times(
        length, extended):
    def load(bitrate_switch: bool) -> BusLoad:
        spec = FrameSpec(0x100, length, 1000.0, extended=extended, fd=True,
                         bitrate_switch=bitrate_switch)
        return bus_load(500_000, [spec], data_bitrate=2_000_000)

    switched, unswitched = load(True), load(False)
    assert switched.nominal_bits_per_second < unswitched.nominal_bits_per_second
    assert switched.worst_bits_per_second < unswitched.worst_bits_per_second
    assert switched.frames_per_second == unswitched.frames_per_second == 1000.0
