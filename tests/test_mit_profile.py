"""The MIT motor protocol: packing against hand-computed firmware vectors, the motor's
impedance law, special frames, and garbage on the bus."""

from __future__ import annotations

import threading
import time
import uuid

import can
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from conftest import TESTS
from hil.bus_config import load_bus_config
from hil.bus_config.types import DriveConfig
from hil.can.frame import Frame
from hil.can.router import start_router
from hil.drives import DriveCore, DriveParameters, Mode, Power
from hil.drives.profile import DriveProfile
from hil.protocols.mit import (
    ENTER_MOTOR_MODE, EXIT_MOTOR_MODE, SET_ZERO, MitCommand, MitOptions, MitRanges, MitReply,
    TimeoutReaction, float_to_uint, pack_command, pack_reply, unpack_command, unpack_reply,
)
from hil.protocols.mit.drive import MitDrive
from hil.testing import DrivesBench

#: judged against the host's stalls (tests/host_stalls.py): the drive answers in its own thread;
#: a test gives it a few ms
pytestmark = pytest.mark.real_time(margin=0.01)

CLASSIC = MitRanges(p_max=12.5, v_max=65.0, kp_max=500.0, kd_max=5.0, t_max=18.0)

# Vectors worked out by hand from the mini-cheetah firmware's float_to_uint (truncating)
# and its pack_cmd / pack_reply bit layout, with the classic ranges:
#   x_int = (int)((x - min) * (2^bits - 1) / (max - min))
COMMAND_VECTORS = [
    # p, v, kp, kd, t_ff -> bytes
    ((0.0, 0.0, 0.0, 0.0, 0.0), "7FFF7FF0000007FF"),     # 32767, 2047, 0, 0, 2047
    ((12.5, -65.0, 500.0, 5.0, -18.0), "FFFF000FFFFFF000"),  # 65535, 0, 4095, 4095, 0
    ((1.0, 2.0, 50.0, 1.0, 0.5), "8A3C83E199333838"),    # 35388, 2110, 409, 819, 2104
    ((99.0, 99.0, 999.0, -1.0, 99.0), "FFFFFFFFFF000FFF"),  # clamped to the ranges
]
REPLY_VECTORS = [
    # motor id, p, v, torque -> bytes
    ((3, -1.0, -2.0, -0.5), "0375C27C07C6"),              # 30146, 1984, 1990
    ((1, 0.0, 0.0, 0.0), "017FFF7FF7FF"),                 # 32767, 2047, 2047
]


@pytest.mark.parametrize("values, expected", COMMAND_VECTORS)
def test_command_packing_matches_the_firmware_vectors(values, expected):
    assert pack_command(MitCommand(*values), CLASSIC).hex().upper() == expected


@pytest.mark.parametrize("values, expected", REPLY_VECTORS)
def test_reply_packing_matches_the_firmware_vectors(values, expected):
    assert pack_reply(MitReply(*values), CLASSIC).hex().upper() == expected
    decoded = unpack_reply(bytes.fromhex(expected), CLASSIC)
    assert decoded.motor_id == values[0]
    for got, meant, span, bits in zip((decoded.position, decoded.velocity, decoded.torque),
                                      values[1:], (25.0, 130.0, 36.0), (16, 12, 12)):
        assert abs(got - meant) <= span / ((1 << bits) - 1)          # within 1 LSB


@settings(max_examples=300, deadline=None)
@given(st.floats(-12.5, 12.5), st.floats(-65, 65), st.floats(0, 500), st.floats(0, 5),
       st.floats(-18, 18))
def test_commands_survive_packing_within_one_lsb(p, v, kp, kd, t):
    decoded = unpack_command(pack_command(MitCommand(p, v, kp, kd, t), CLASSIC), CLASSIC)
    for got, meant, span, bits in zip(
            (decoded.position, decoded.velocity, decoded.kp, decoded.kd, decoded.torque),
            (p, v, kp, kd, t), (25.0, 130.0, 500.0, 5.0, 36.0), (16, 12, 12, 12, 12)):
        assert abs(got - meant) <= span / ((1 << bits) - 1) + 1e-9


def test_float_to_uint_truncates_like_the_firmware():
    assert float_to_uint(0.0, -12.5, 12.5, 16) == 32767            # 32767.5 truncated
    assert float_to_uint(-12.5, -12.5, 12.5, 16) == 0
    assert float_to_uint(12.5, -12.5, 12.5, 16) == 65535


def core(peak: float = 2.0, watchdog: float = 0.0) -> DriveCore:
    return DriveCore(DriveParameters(
        counts_per_rev=1 << 20, rated_torque=1.0, peak_torque=peak, position_kp=10,
        velocity_kp=0.1, velocity_ki=1.0, max_velocity=100.0, following_error_limit=0.0,
        following_error_timeout=0.01, quick_stop_deceleration=100.0,
        watchdog_timeout=watchdog, holding_brake=False))


def test_impedance_mode_applies_kp_kd_and_feed_forward_and_saturates():
    drive = core(peak=2.0)
    drive.set_mode(Mode.IMPEDANCE)
    drive.measure(0.10, 0.5)
    drive.enable()
    drive.new_setpoint(position=0.30, velocity=1.5, torque=0.05, stiffness=4.0, damping=0.2)
    # 4 (0.3 - 0.1) + 0.2 (1.5 - 0.5) + 0.05 = 1.05 (position quantised to 2^20 counts)
    assert drive.update(0.001) == pytest.approx(1.05, abs=1e-4)
    drive.new_setpoint(position=3.0)
    assert drive.update(0.001) == pytest.approx(2.0)                # the peak torque


def drive_config(node_id: int, protocol: str, options) -> DriveConfig:
    """The bus config entry a MIT-family drive is built from, off any bus config: its node id
    and options (the rest is its core's, given apart)."""
    return DriveConfig(node_id=node_id, actuator="motor", joints=("yaw",), protocol=protocol,
                       encoder_counts_per_rev=1 << 20, rated_torque=1.0, peak_torque=2.0,
                       max_velocity=100.0, following_error_limit=0.0,
                       following_error_timeout=0.01, quick_stop_deceleration=100.0,
                       watchdog_timeout=0.0, heartbeat_period=0.1, holding_brake=False,
                       position_limits=None, gains=None, velocity_bandwidth_hz=40.0,
                       options=options)


class MitBench:
    """One MitDrive on a python-can virtual bus, and a master bus to talk to it."""

    def __init__(self, node_id: int = 5, options: MitOptions = MitOptions(ranges=CLASSIC,
                                                                          kp=10.0, kd=0.1)):
        channel = f"hil-mit-{uuid.uuid4().hex[:8]}"
        self.drive_bus = can.Bus(interface="virtual", channel=channel)
        self.master = can.Bus(interface="virtual", channel=channel)
        self.lock = threading.RLock()
        self.core = core(peak=options.ranges.t_max)
        self.drive = MitDrive(drive_config(node_id, "mit", options), self.core, self.lock)
        self.drive.on_command = lambda d: d.send_replies()        # real time: answer at once
        self.router = start_router(self.drive_bus, keep_sending=True)
        self.drive.attach(self.router)
        self.options = options

    def send(self, data: bytes, can_id: int | None = None) -> MitReply | None:
        self.master.send(can.Message(arbitration_id=self.drive.node_id if can_id is None
                                     else can_id, data=data, is_extended_id=False))
        reply = self.master.recv(5.0)       # patient: what it answers, not how fast
        return None if reply is None else unpack_reply(bytes(reply.data), self.options.ranges)

    def close(self):
        self.drive.detach()
        self.router.stop(1)
        self.drive_bus.shutdown()
        self.master.shutdown()


@pytest.fixture
def mit():
    bench = MitBench()
    yield bench
    bench.close()


def test_special_frames_enter_and_exit_motor_mode_and_set_zero(mit):
    mit.core.measure(1.0, 0.0)
    reply = mit.send(ENTER_MOTOR_MODE)
    assert mit.core.power is Power.ENABLED and reply.motor_id == 5
    assert reply.position == pytest.approx(1.0, abs=25 / 65535)
    mit.send(SET_ZERO)
    assert mit.send(pack_command(MitCommand(0, 0, 0, 0, 0), CLASSIC)).position == \
        pytest.approx(0.0, abs=25 / 65535)
    mit.send(EXIT_MOTOR_MODE)
    assert mit.core.power is Power.DISABLED


def test_commands_are_ignored_in_rest_mode_but_answered(mit):
    reply = mit.send(pack_command(MitCommand(3.0, 0, 100, 1, 5.0), CLASSIC))
    assert reply is not None and mit.core.power is Power.DISABLED
    assert mit.core.update(0.001) == 0.0


@pytest.mark.slow
@settings(max_examples=200, deadline=None)
@given(st.binary(min_size=0, max_size=8))
def test_garbage_and_truncated_frames_never_crash_the_motor(data):
    bench = MitBench()
    try:
        bench.master.send(can.Message(arbitration_id=5, data=data, is_extended_id=False))
        time.sleep(0.002)
        reply = bench.send(ENTER_MOTOR_MODE)      # still alive and answering
        assert reply is not None and reply.motor_id == 5
        if len(data) != 8:
            assert bench.drive.malformed >= 1
    finally:
        bench.close()


def test_options_are_validated_with_the_key_named():
    with pytest.raises(ValueError, match="'kp'"):
        MitOptions.from_mapping({"kp": 0})
    with pytest.raises(ValueError, match="'v_max'"):
        MitOptions.from_mapping({"v_max": -1, "kp": 1})
    with pytest.raises(ValueError, match="reply_id"):
        MitOptions.from_mapping({"reply_id": 4096, "kp": 1})
    with pytest.raises(ValueError, match="'timeout_reaction' 'stop' is not one of zero, rest"):
        MitOptions.from_mapping({"timeout_reaction": "stop", "kp": 1})


# --- the CAN timeout, lock-step --------------------------------------------------------

class LockStep:
    """A MIT-family drive off any bus, in lock-step: the test hands it its frames and steps
    its clock; at each step the simulator's watchdog check and after_update run (the plant
    stands still). The clock starts where time.monotonic is, so a drive that fed its
    watchdog on the real clock (as before issue 64) is judged on the same scale; from there
    only the test moves it."""

    def __init__(self, drive: DriveProfile):
        self.drive, self.core = drive, drive.core
        self.now = time.monotonic()
        drive.clock = lambda: self.now
        self.handlers = {(subscription.identifier, subscription.extended): subscription.handler
                         for subscription in drive.subscriptions()}

    def send(self, can_id: int, data: bytes, extended: bool = False) -> None:
        self.handlers[can_id, extended](Frame(can_id, data, extended))

    def wait(self, seconds: float, step: float = 0.002) -> None:
        for _ in range(round(seconds / step)):
            self.now += step
            self.core.check_watchdog(self.now)
            self.drive.after_update()

    def states_re_enabled_after_a_pause(self, can_id: int, enable: bytes, disable: bytes,
                                        command: bytes) -> set[str]:
        """Issue 64's sequence: enable, command, disable, 0.4 s, enable, then a command every
        2 ms for 0.2 s; the drive's states after each of those commands."""
        for frame in (enable, command, disable):
            self.send(can_id, frame)
        self.wait(0.4)
        self.send(can_id, enable)
        states = set()
        for _ in range(100):
            self.wait(0.002)
            self.send(can_id, command)
            states.add(self.drive.state_text)
        return states


def lock_step_mit(reaction: TimeoutReaction = TimeoutReaction.ZERO) -> LockStep:
    """Motor 5 at rest at 0 rad, its CAN timeout 0.1 s."""
    options = MitOptions(ranges=CLASSIC, kp=10.0, kd=0.1, timeout_reaction=reaction)
    drive = MitDrive(drive_config(5, "mit", options), core(peak=CLASSIC.t_max, watchdog=0.1),
                     threading.RLock())
    drive.core.measure(0.0, 0.0)
    return LockStep(drive)


#: 1 rad from the motor at kp 10: about 10 N·m (kp and the position as the frame carries them)
PULL = pack_command(MitCommand(1.0, 0.0, 10.0, 0.0, 0.0), CLASSIC)
PULLED = unpack_command(PULL, CLASSIC).kp * unpack_command(PULL, CLASSIC).position


def test_re_enabling_after_a_pause_does_not_trip_the_can_timeout():
    """Issue 64: enable, command, disable, 0.4 s, enable, a command every 2 ms: the motor fell
    to rest mode at once (the time of the command before the disable counted). Ben Katz's
    Hobbyking_Cheetah_Compact main.cpp: every frame to the motor zeroes the timeout counter
    (onMsgReceived), which counts in motor mode only."""
    motor = lock_step_mit(TimeoutReaction.REST)      # a trip would show as rest mode
    assert motor.states_re_enabled_after_a_pause(5, ENTER_MOTOR_MODE, EXIT_MOTOR_MODE,
                                                 PULL) == {"MOTOR MODE"}
    assert motor.core.update(0.001) == pytest.approx(PULLED, abs=0.01)


def test_a_can_timeout_zeroes_the_gains_and_the_next_command_drives_again():
    """Issue 64: after a timeout hil's motor left motor mode, so later commands moved nothing.
    Hobbyking_Cheetah_Compact (its 40 kHz interrupt, MOTOR_MODE) and bgkatz/motorcontrol
    (fsm.c, zero_commands) zero kp, kd and the feed-forward and stay in motor mode."""
    motor = lock_step_mit()
    motor.send(5, ENTER_MOTOR_MODE)
    motor.send(5, PULL)
    assert motor.core.update(0.001) == pytest.approx(PULLED, abs=0.01)
    motor.wait(0.2)                                   # silent past the 0.1 s timeout
    assert motor.drive.state_text == "MOTOR MODE" and motor.core.update(0.001) == 0.0
    motor.send(5, PULL)
    assert motor.core.update(0.001) == pytest.approx(PULLED, abs=0.01)


def test_timeout_reaction_rest_leaves_motor_mode_until_entered_again():
    """The forks that drop to the menu on a timeout: ``timeout_reaction: rest``."""
    motor = lock_step_mit(TimeoutReaction.REST)
    motor.send(5, ENTER_MOTOR_MODE)
    motor.send(5, PULL)
    motor.wait(0.2)
    assert motor.drive.state_text == "REST MODE"
    motor.send(5, PULL)
    assert motor.core.update(0.001) == 0.0
    motor.send(5, ENTER_MOTOR_MODE)
    motor.send(5, PULL)
    assert motor.core.update(0.001) == pytest.approx(PULLED, abs=0.01)


def test_the_default_watchdog_is_the_firmwares_none(tmp_path):
    """Issue 64: hil's 0.1 s was tighter than published clients assume. A drive's
    ``watchdog_timeout`` defaults to the firmware's CAN_TIMEOUT where the flash holds none:
    0, "none" (Hobbyking_Cheetah_Compact main.cpp, main())."""
    fixture = TESTS / "fixtures" / "damiao_one_axis.yaml"
    text = fixture.read_text().replace(
        "defaults: {protocol: damiao, watchdog_timeout: 0.5}", "defaults: {protocol: mit}")
    text = text.replace("options: {model: DM4310, master_id: 0x11, kp: 5.0, kd: 0.3}",
                        "options: {kp: 5.0, kd: 0.3}")
    path = tmp_path / "mit.yaml"
    path.write_text(text.replace("robot: damiao_one_axis.urdf",
                                 f"robot: {fixture.parent / 'damiao_one_axis.urdf'}"))
    assert load_bus_config(path).buses[0].drives[0].watchdog_timeout == 0.0


# --- a master on the plant, lock-step ----------------------------------------------------

class PlantMaster:
    """A master on a lock-step DrivesBench of a one-joint bus config (the drive on its
    plant): each frame sent closes a cycle of its own, and brings the answers to it."""

    def __init__(self, bench: DrivesBench):
        self.bench, self.bus = bench, bench.bus()
        self.period = 1 / bench.config.buses[0].cycle_hz

    def send(self, can_id: int, data: bytes, extended: bool = False) -> list[can.Message]:
        self.bus.send(can.Message(arbitration_id=can_id, data=data, is_extended_id=extended))
        self.bench.step()
        return list(iter(lambda: self.bus.recv(0), None))

    def wait(self, seconds: float) -> None:
        self.bench.step(round(seconds / self.period))

    def joint(self) -> float:
        return next(iter(self.bench.joints().values()))
