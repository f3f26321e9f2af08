"""hil-virtual: python-can's in-process bus without deep copies, with direct delivery."""

from __future__ import annotations

import logging
import threading
import uuid

import can
import pytest

from hil.can.faults import FaultyBus, FrameFault
from hil.can.messages import EXTENDED, data_frame, extended
from hil.can.network import start_network
from conftest import FrameRecorder


@pytest.fixture
def channel():
    return f"hil-virtual-{uuid.uuid4().hex[:8]}"


@pytest.fixture
def pair(channel):
    sender = can.Bus(interface="hil-virtual", channel=channel)
    receiver = can.Bus(interface="hil-virtual", channel=channel)
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


@pytest.mark.parametrize("arbitration_id, data, remote", [
    (0x201, b"\x0f\x00\x10\x27\x00\x00", False), (0x1ABCDE, bytearray(b"\x01"), False),
    (0x080, b"", False), (0x701, b"", True), (0x581, [1, 2, 3], False)])
def test_data_frame_builds_what_the_message_constructor_builds(arbitration_id, data, remote):
    expected = can.Message(arbitration_id=arbitration_id, data=data, is_remote_frame=remote,
                           is_extended_id=arbitration_id > 0x7FF)
    built = data_frame(arbitration_id, data, remote)
    fields = [name for name in can.Message.__slots__ if name != "__weakref__"]
    assert {name: getattr(built, name) for name in fields} == \
        {name: getattr(expected, name) for name in fields}
    assert (built.data is data) == (expected.data is data)     # a bytearray is not copied


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


def test_a_networks_listener_feeds_subscribers_routes_rtr_and_survives_a_failing_one(
        pair, caplog):
    sender, receiver = pair
    network = start_network(receiver)
    heard, asked = [], []

    def broken(can_id, data, timestamp):
        raise RuntimeError("broken subscriber")

    def hear(can_id, data, timestamp):
        heard.append((can_id, bytes(data)))

    network.subscribe(0x181, broken)
    network.subscribe(0x181, hear)        # after the failing one, on the same id
    network.subscribe(0x182, hear)
    network.frame_listener.remote_handlers[0x209] = asked.append
    with caplog.at_level(logging.WARNING):
        sender.send(frame(0x181))
        sender.send(frame(0x182, b"\x01"))
        sender.send(can.Message(arbitration_id=0x209, is_remote_frame=True, dlc=8,
                                is_extended_id=False))
    assert heard == [(0x181, frame().data), (0x182, b"\x01")] and asked == [0x209]
    assert "0x181" in caplog.text and "broken subscriber" in caplog.text
    assert "Traceback" not in caplog.text             # one line, counted
    assert network.frame_listener.refused == 1
    network.notifier.stop()


@pytest.fixture
def networks(pair):
    sender, receiver = pair
    ends = start_network(sender), start_network(receiver)
    yield ends
    for network in ends:
        network.notifier.stop()


def _hear(network, key: int) -> list:
    heard = []
    network.subscribe(key, lambda can_id, data, timestamp: heard.append((can_id, data)))
    return heard


def test_hils_networks_exchange_frames_as_parts_without_building_a_message(
        networks, monkeypatch):
    sent, received = networks
    import hil.can.network
    import hil.can.virtual

    def no_message(*args, **kwargs):
        raise AssertionError("a can.Message was built between two of hil's networks")

    for module, builder in ((hil.can.network, "data_frame"), (hil.can.virtual, "data_frame"),
                            (hil.can.virtual, "received_copy")):
        monkeypatch.setattr(module, builder, no_message)
    heard = _hear(received, 0x181)
    payload = bytearray(b"\x27\x00\x10\x00")
    sent.send_message(0x181, payload)
    payload[0] = 0xFF                      # the sender's buffer is its own again
    assert heard == [(0x181, bytearray(b"\x27\x00\x10\x00"))]
    assert type(heard[0][1]) is bytearray  # the receiver's own copy, as a message's data


def test_a_frame_sent_as_parts_reaches_python_cans_buses_as_the_message_it_stands_for(
        networks, channel):
    sent, _ = networks
    plain = can.Bus(interface="virtual", channel=channel)
    try:
        for can_id, data in ((0x181, b"\x01\x02"), (0x1ABCDE, b"\x03"),
                             (0x101 | EXTENDED, b""), (0x080, b"")):
            sent.send_message(can_id, data)
            expected = data_frame(can_id, data)
            got = plain.recv(1)
            assert (got.arbitration_id, got.is_extended_id, got.dlc, bytes(got.data),
                    got.is_remote_frame, got.is_rx) == (
                expected.arbitration_id, expected.is_extended_id, expected.dlc,
                bytes(expected.data), False, True)
    finally:
        plain.shutdown()


def test_frames_as_parts_keep_standard_and_extended_ids_of_one_number_apart(networks):
    sent, received = networks
    standard, extended_heard = _hear(received, 0x101), _hear(received, extended(0x101))
    long_id = _hear(received, 0x1ABCDE)
    sent.send_message(0x101, b"\x01")
    sent.send_message(0x101 | EXTENDED, b"\x02")
    sent.send_message(0x1ABCDE, b"\x03")
    assert standard == [(0x101, b"\x01")]
    assert extended_heard == [(extended(0x101), b"\x02")]
    assert long_id == [(0x1ABCDE, b"\x03")]


def test_a_listener_that_wants_messages_added_later_gets_them_beside_the_network(
        networks):
    sent, received = networks
    heard = _hear(received, 0x181)
    recorder = FrameRecorder()
    received.notifier.add_listener(recorder)
    sent.send_message(0x181, b"\x05")
    assert heard == [(0x181, b"\x05")]
    (message, _), = recorder.frames
    assert (message.arbitration_id, bytes(message.data)) == (0x181, b"\x05")


def test_a_remote_request_between_hils_networks_goes_as_a_message_to_its_handler(networks):
    sent, received = networks
    asked = []
    received.frame_listener.remote_handlers[0x281] = asked.append
    sent.send_message(0x281, b"", remote=True)
    assert asked == [0x281]


def test_frames_sent_at_once_reach_every_receiver_frame_by_frame_in_order(networks, channel):
    sent, first = networks
    second = start_network(can.Bus(interface="hil-virtual", channel=channel))
    try:
        heard = []
        for name, network in (("first", first), ("second", second)):
            for key in (0x181, extended(0x101), 0x1ABCDE):
                network.subscribe(key, lambda can_id, data, timestamp, name=name:
                                  heard.append((name, can_id, bytes(data))))
        sent.send_frames([(0x181, b"\x01"), (0x101 | EXTENDED, b"\x02"), (0x1ABCDE, b"\x03")])
        # as one send after another: each frame at every receiver before the next at any
        assert [(can_id, data) for _, can_id, data in heard] == [
            (0x181, b"\x01"), (0x181, b"\x01"), (extended(0x101), b"\x02"),
            (extended(0x101), b"\x02"), (0x1ABCDE, b"\x03"), (0x1ABCDE, b"\x03")]
        assert {name for name, _, _ in heard[:2]} == {"first", "second"}
    finally:
        second.notifier.stop()
        second.bus.shutdown()


def test_frames_sent_at_once_reach_python_cans_bus_as_messages_in_order(networks, channel):
    sent, _ = networks
    plain = can.Bus(interface="virtual", channel=channel)
    try:
        sent.send_frames([(0x181, b"\x01"), (0x182, b"\x02"), (0x181, b"\x03")])
        got = [plain.recv(1) for _ in range(3)]
        assert [(m.arbitration_id, bytes(m.data)) for m in got] == [
            (0x181, b"\x01"), (0x182, b"\x02"), (0x181, b"\x03")]
        assert plain.recv(0) is None
    finally:
        plain.shutdown()


def test_a_drive_network_counts_every_frame_of_a_batch_its_closed_bus_refuses(
        channel, caplog):
    from hil.drives.profile import DriveNetwork
    bus = can.Bus(interface="hil-virtual", channel=channel)
    network = start_network(bus, 0.1, DriveNetwork)
    network.notifier.stop()
    bus.shutdown()
    with caplog.at_level(logging.WARNING):
        network.send_frames([(0x181, b"\x01"), (0x281, b"\x02"), (0x381, b"\x03")])
        network.send_frames([(0x181, b"\x01")])
    assert network.lost_frames == 4
    assert len([r for r in caplog.records if "was lost" in r.getMessage()]) == 1


def test_a_delivery_stopped_by_its_listener_mid_batch_delivers_no_more_of_it(networks):
    sent, received = networks
    heard = []

    def stop_at_the_second(can_id, data, timestamp):
        heard.append(bytes(data))
        if len(heard) == 2:
            received.notifier.stop()

    received.subscribe(0x181, stop_at_the_second)
    sent.send_frames([(0x181, b"\x01"), (0x181, b"\x02"), (0x181, b"\x03")])
    assert heard == [b"\x01", b"\x02"]
