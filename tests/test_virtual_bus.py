"""hil-virtual: python-can's in-process bus without deep copies, with direct delivery."""

from __future__ import annotations

import logging
import threading
import uuid

import can
import pytest

from hil.can.faults import FaultyBus, FrameFault
from hil.can.frame import Frame
from hil.can.messages import frame_of, message_of
from hil.can.router import FrameRouter, start_router
from conftest import FrameRecorder


@pytest.fixture
def channel():
    return f"hil-virtual-{uuid.uuid4().hex[:8]}"


@pytest.fixture
def pair(channel):
    """Two ends of one channel, each opened for CAN FD frames too (python-can's fd=True)."""
    sender = can.Bus(interface="hil-virtual", channel=channel, fd=True)
    receiver = can.Bus(interface="hil-virtual", channel=channel, fd=True)
    yield sender, receiver
    sender.shutdown()
    receiver.shutdown()


def frame(arbitration_id: int = 0x181, data: bytes = b"\x27\x00\x10\x00\x00\x00"):
    return can.Message(arbitration_id=arbitration_id, data=data, is_extended_id=False)


def test_direct_delivery_hands_the_frame_over_in_the_senders_thread(pair):
    sender, receiver = pair
    recorder = FrameRecorder()
    receiver.deliver_to([recorder])
    sender.send(frame())
    (received, thread), = recorder.frames            # already there when send returns
    assert thread == threading.get_ident()
    assert (received.arbitration_id, bytes(received.data)) == (0x181, frame().data)
    assert received.is_rx and received.channel == sender.channel_id
    assert receiver.recv(0) is None                  # nothing queued besides


def test_each_receiver_gets_its_own_copy(pair):
    sender, receiver = pair
    sent = frame()
    sender.send(sent)
    received = receiver.recv(1)
    received.data[0] = 0xFF
    assert sent.data[0] == 0x27


#: can.Message's fields (its slots but the weak reference)
FIELDS = [name for name in can.Message.__slots__ if name != "__weakref__"]

#: frames of every kind a Frame says: standard, extended (one a standard id could carry), a
#: remote request with its DLC, CAN FD with and without the bit-rate switch, an error frame
BUILT = [Frame(0x201, b"\x0f\x00\x10\x27\x00\x00"),
         Frame(0x1ABCDE, b"\x01", extended=True),
         Frame(0x101, b"", extended=True),
         Frame(0x080, timestamp=12.5),
         Frame(0x701, bytes(8), remote=True),
         Frame(0x123, bytes(3), extended=True, remote=True),
         Frame(0x1ABCDEF0, bytes(range(64)), extended=True, fd=True, bitrate_switch=True),
         Frame(0x181, bytes(12), fd=True),
         Frame(0x0, bytes(8), error=True)]


def _constructed(frame: Frame, channel=None, is_rx: bool = False) -> can.Message:
    """What python-can's constructor builds for ``frame`` (a remote frame: no data, its DLC)."""
    return can.Message(timestamp=frame.timestamp, arbitration_id=frame.identifier,
                       is_extended_id=frame.extended, is_remote_frame=frame.remote,
                       is_error_frame=frame.error, channel=channel,
                       dlc=len(frame.data) if frame.remote else None,
                       data=None if frame.remote else frame.data, is_fd=frame.fd,
                       is_rx=is_rx, bitrate_switch=frame.bitrate_switch)


@pytest.mark.parametrize("channel, is_rx", [(None, False), ("arm", True)])
@pytest.mark.parametrize("frame", BUILT, ids=str)
def test_message_of_builds_what_the_message_constructor_builds(frame, channel, is_rx):
    built = message_of(frame, channel, is_rx)
    assert {name: getattr(built, name) for name in FIELDS} == \
        {name: getattr(_constructed(frame, channel, is_rx), name) for name in FIELDS}
    assert type(built.data) is bytearray                # a message's data, its own


@pytest.mark.parametrize("frame", BUILT, ids=str)
def test_frame_of_takes_every_field_of_what_the_message_constructor_builds(frame):
    msg = _constructed(frame, "arm", True)
    taken = frame_of(msg)
    assert taken == frame and type(taken.data) is bytes
    assert frame_of(msg, timestamp=3.25) == frame._replace(timestamp=3.25)
    assert {name: getattr(message_of(taken, "arm", True), name) for name in FIELDS} == \
        {name: getattr(msg, name) for name in FIELDS}


def test_a_received_copy_has_every_field_of_the_frame_it_copies(pair):
    """The copy is built slot by slot: a field python-can adds to can.Message must not be
    left unset."""
    sender, receiver = pair
    sent = can.Message(arbitration_id=0x1ABCDE, data=b"\x01\x02\x03", is_extended_id=True,
                       is_fd=True, bitrate_switch=True, error_state_indicator=True, dlc=3)
    sender.send(sent)
    received = receiver.recv(1)
    fields = [name for name in can.Message.__slots__ if name != "__weakref__"]
    for name in fields:
        getattr(received, name)                      # set, or AttributeError
    same = set(fields) - {"timestamp", "channel", "is_rx"}      # what receiving changes
    assert {name: getattr(received, name) for name in same} == \
        {name: getattr(sent, name) for name in same}
    assert received.is_rx and received.channel == sender.channel_id


def test_stopping_direct_delivery_waits_for_a_frame_in_progress_and_delivers_no_more(pair):
    sender, receiver = pair
    inside, release = threading.Event(), threading.Event()
    heard = []

    class Slow(can.Listener):
        def on_message_received(self, msg):
            heard.append(msg.data[0])
            inside.set()
            release.wait(5)

    delivery = receiver.deliver_to([Slow()])
    sending = threading.Thread(target=sender.send, args=(frame(data=b"\x01"),))
    sending.start()
    assert inside.wait(5)
    stopping = threading.Thread(target=delivery.stop)
    stopping.start()
    stopping.join(0.3)
    assert stopping.is_alive()              # still waiting for the frame being delivered
    release.set()
    stopping.join(5)
    sending.join(5)
    assert not stopping.is_alive()
    delivery.deliver(frame(data=b"\x02"))   # a frame that slipped past the bus' check
    assert heard == [1]


def test_a_listener_that_raises_does_not_keep_the_frame_from_the_others(pair):
    sender, receiver = pair

    class Broken(can.Listener):
        def on_message_received(self, msg):
            raise RuntimeError("broken listener")

    recorder = FrameRecorder()
    receiver.deliver_to([Broken(), recorder])
    sender.send(frame())
    assert len(recorder.frames) == 1


def test_stopped_delivery_queues_frames_for_recv_again(pair):
    sender, receiver = pair
    recorder = FrameRecorder()
    receiver.deliver_to([recorder]).stop()
    sender.send(frame())
    assert recorder.frames == []
    assert receiver.recv(1).arbitration_id == 0x181


def test_python_cans_own_virtual_bus_on_the_channel_hears_and_is_heard(pair, channel):
    sender, receiver = pair
    plain = can.Bus(interface="virtual", channel=channel)
    try:
        sender.send(frame(0x201))
        assert plain.recv(1).arbitration_id == 0x201
        assert receiver.recv(1).arbitration_id == 0x201
        plain.send(frame(0x202))
        assert receiver.recv(1).arbitration_id == 0x202
    finally:
        plain.shutdown()


def test_python_cans_own_virtual_bus_hands_its_frame_to_a_direct_delivery_at_once(
        pair, channel):
    """Issue 64: a frame of python-can's ``virtual`` bus waited in the queue of a bus that
    delivered directly, read by no one (a lock-step DrivesBench lost the MIT answers of its
    master's commands). python-can's VirtualBus.send puts each frame into every receiver's
    queue: a hil-virtual bus' queue hands it to the delivery, in the sender's thread."""
    _, receiver = pair
    recorder = FrameRecorder()
    receiver.deliver_to([recorder])
    plain = can.Bus(interface="virtual", channel=channel)
    try:
        plain.send(frame(0x203))
        (received, thread), = recorder.frames        # already there when send returns
        assert received.arbitration_id == 0x203 and thread == threading.get_ident()
        assert receiver.recv(0) is None
    finally:
        plain.shutdown()


def test_a_faulty_bus_applies_its_receive_faults_to_direct_delivery(pair):
    sender, receiver = pair
    faulty = FaultyBus(receiver, [])
    recorder = FrameRecorder()
    try:
        assert faulty.deliver_to([recorder]) is not None
        sender.send(frame())
        faulty.add(FrameFault("drop", "arm", 1.0))
        sender.send(frame())
        assert len(recorder.frames) == 1 and faulty.injected["drop"] == 1
    finally:
        faulty.shutdown()


def test_a_faulty_bus_over_a_bus_without_direct_delivery_offers_none(channel):
    plain = can.Bus(interface="virtual", channel=channel)
    faulty = FaultyBus(plain, [])
    try:
        assert faulty.deliver_to([FrameRecorder()]) is None
    finally:
        faulty.shutdown()


def test_a_routers_subscribers_hear_pythoncan_sends_remote_frames_apart_a_failing_one_aside(
        pair, caplog):
    sender, receiver = pair
    router = start_router(receiver)
    heard, asked = [], []

    def broken(frame):
        raise RuntimeError("broken subscriber")

    router.subscribe(0x181, broken)
    router.subscribe(0x181, heard.append)      # after the failing one, on the same id
    router.subscribe(0x182, heard.append)
    router.subscribe(0x209, asked.append, remote=True)
    with caplog.at_level(logging.WARNING):
        sender.send(frame(0x181))
        sender.send(frame(0x182, b"\x01"))
        sender.send(can.Message(arbitration_id=0x209, is_remote_frame=True, dlc=8,
                                is_extended_id=False))
    assert [(each.identifier, each.data) for each in heard] == [(0x181, frame().data),
                                                                (0x182, b"\x01")]
    assert [(each.identifier, each.remote, each.data) for each in asked] == [
        (0x209, True, bytes(8))]                  # a remote frame's DLC, as zero bytes
    assert "0x181" in caplog.text and "broken subscriber" in caplog.text
    assert "Traceback" not in caplog.text             # one line, counted
    assert router.refused == 1
    router.stop()


@pytest.fixture
def routers(pair):
    sender, receiver = pair
    ends = start_router(sender), start_router(receiver)
    yield ends
    for router in ends:
        router.stop()


def _hear(router: FrameRouter, identifier: int, extended: bool = False) -> list[Frame]:
    heard: list[Frame] = []
    router.subscribe(identifier, heard.append, extended)
    return heard


def test_hils_routers_exchange_frames_as_values_without_building_a_message(
        routers, monkeypatch):
    sent, received = routers
    import hil.can.delivery
    import hil.can.router
    import hil.can.virtual

    def no_message(*args, **kwargs):
        raise AssertionError("a can.Message was built between two of hil's routers")

    for module, builder in ((hil.can.router, "message_of"), (hil.can.virtual, "message_of"),
                            (hil.can.virtual, "received_copy"),
                            (hil.can.delivery, "message_of")):
        monkeypatch.setattr(module, builder, no_message)
    heard = _hear(received, 0x181)
    cycle = Frame(0x181, b"\x27\x00\x10\x00")
    sent.send(cycle)
    assert heard == [cycle] and heard[0] is cycle     # immutable: handed over as it is


@pytest.mark.parametrize("sent_frame", [
    Frame(0x181, b"\x01\x02"), Frame(0x1ABCDE, b"\x03", extended=True),
    Frame(0x101, b"", extended=True), Frame(0x080), Frame(0x209, bytes(8), remote=True),
    Frame(0x1ABCDEF0, bytes(range(64)), extended=True, fd=True, bitrate_switch=True)],
    ids=str)
def test_a_frame_sent_as_a_value_reaches_python_cans_buses_as_the_message_it_stands_for(
        routers, channel, sent_frame):
    sent, _ = routers
    plain = can.Bus(interface="virtual", channel=channel)
    try:
        sent.send(sent_frame)
        got = plain.recv(1)
        assert got.is_rx and got.channel == channel
        assert got.equals(_constructed(sent_frame), timestamp_delta=None,
                          check_channel=False, check_direction=False)
    finally:
        plain.shutdown()


def test_frames_as_values_keep_standard_and_extended_ids_of_one_number_apart(routers):
    sent, received = routers
    standard, extended_heard = _hear(received, 0x101), _hear(received, 0x101, extended=True)
    long_id = _hear(received, 0x1ABCDE, extended=True)
    sent.send(Frame(0x101, b"\x01"))
    sent.send(Frame(0x101, b"\x02", extended=True))
    sent.send(Frame(0x1ABCDE, b"\x03", extended=True))
    assert standard == [Frame(0x101, b"\x01")]
    assert extended_heard == [Frame(0x101, b"\x02", extended=True)]
    assert long_id == [Frame(0x1ABCDE, b"\x03", extended=True)]


def test_a_listener_that_wants_messages_added_later_gets_them_beside_the_router(pair):
    sender, receiver = pair
    router = FrameRouter(receiver)
    delivery = receiver.deliver_to([router])
    heard = _hear(router, 0x181)
    recorder = FrameRecorder()
    delivery.add_listener(recorder)
    FrameRouter(sender).send(Frame(0x181, b"\x05"))
    assert [(each.identifier, each.data) for each in heard] == [(0x181, b"\x05")]
    (message, _), = recorder.frames
    assert (message.arbitration_id, bytes(message.data)) == (0x181, b"\x05")
    delivery.stop()


def test_a_remote_request_between_hils_routers_reaches_its_remote_subscriber_only(routers):
    sent, received = routers
    asked, data = [], _hear(received, 0x281)
    received.subscribe(0x281, asked.append, remote=True)
    request = Frame(0x281, b"", remote=True)
    sent.send(request)
    assert asked == [request] and data == []


def test_frames_sent_at_once_reach_every_receiver_frame_by_frame_in_order(routers, channel):
    sent, first = routers
    second = start_router(can.Bus(interface="hil-virtual", channel=channel))
    cycle = [Frame(0x181, b"\x01"), Frame(0x101, b"\x02", extended=True),
             Frame(0x1ABCDE, b"\x03", extended=True)]
    try:
        heard = []
        for name, router in (("first", first), ("second", second)):
            for each in cycle:
                router.subscribe(each.identifier,
                                 lambda got, name=name: heard.append((name, got)),
                                 each.extended)
        sent.send_frames(cycle)
        # as one send after another: each frame at every receiver before the next at any
        assert [got for _, got in heard] == [cycle[0], cycle[0], cycle[1], cycle[1],
                                             cycle[2], cycle[2]]
        assert {name for name, _ in heard[:2]} == {"first", "second"}
    finally:
        second.stop()
        second.bus.shutdown()


def test_frames_sent_at_once_reach_python_cans_bus_as_messages_in_order(routers, channel):
    sent, _ = routers
    plain = can.Bus(interface="virtual", channel=channel)
    try:
        sent.send_frames([Frame(0x181, b"\x01"), Frame(0x182, b"\x02"), Frame(0x181, b"\x03")])
        got = [plain.recv(1) for _ in range(3)]
        assert [(m.arbitration_id, bytes(m.data)) for m in got] == [
            (0x181, b"\x01"), (0x182, b"\x02"), (0x181, b"\x03")]
        assert plain.recv(0) is None
    finally:
        plain.shutdown()


def test_a_keep_sending_router_counts_every_frame_of_a_batch_its_closed_bus_refuses(
        channel, caplog):
    bus = can.Bus(interface="hil-virtual", channel=channel)
    router = start_router(bus, keep_sending=True)
    router.stop()
    bus.shutdown()
    with caplog.at_level(logging.WARNING):
        router.send_frames([Frame(0x181, b"\x01"), Frame(0x281, b"\x02"),
                            Frame(0x381, b"\x03")])
        router.send(Frame(0x181, b"\x01"))
    assert router.lost_frames == 4
    assert len([r for r in caplog.records if "was lost" in r.getMessage()]) == 1


def test_a_delivery_stopped_by_its_listener_mid_batch_delivers_no_more_of_it(routers):
    sent, received = routers
    heard = []

    def stop_at_the_second(got):
        heard.append(got.data)
        if len(heard) == 2:
            received.stop()

    received.subscribe(0x181, stop_at_the_second)
    sent.send_frames([Frame(0x181, b"\x01"), Frame(0x181, b"\x02"), Frame(0x181, b"\x03")])
    assert heard == [b"\x01", b"\x02"]
