"""mjbots' moteus as its documents and firmware describe it: the frame format and the
register subframes against the document's own example, a test per register group, the
modes, the watchdog's position timeout, faults, and the maker's ``moteus`` library
(pinned in the test extra) querying, moving and stopping a simulated controller through its
python-can transport, unchanged.

Sources (github.com/mjbots/moteus): docs/protocol/can.md ("CAN ID", "Subframes",
"Example"), docs/protocol/registers.md ("Mappings", "Registers"), fw/moteus_controller.cc
(``Write``, ``Read``, ``ScaleSaturate``), fw/fdcan_micro_server.h (``AsyncWrite``),
fw/bldc_servo_control.h (``ISR_MaybeChangeMode``, ``ISR_DoControl``); mjlib's
multiplex/micro_server.cc (github.com/mjbots/mjlib)."""

from __future__ import annotations

import asyncio
import math
import threading
import time

import can
import pytest

from conftest import TESTS, hils_master_moves
from hil.bus_config import load_bus_config
from hil.can.frame import Frame
from hil.drives import DriveCore, DriveParameters
from hil.errors import HilError
from hil.protocols import protocol
from hil.protocols.moteus import (
    Moteus, MoteusOptions, identifier, moteus_frame, position_command,
)
from hil.protocols.moteus import multiplex
from hil.protocols.moteus.drive import MoteusDrive
from hil.protocols.moteus.models import CONTROLLERS, MODELS, MOTORS
from hil.protocols.moteus.registers import (
    ACCELERATION, CURRENT, FLOAT, INT8, INT16, INT32, POSITION, POWER, PWM, TEMPERATURE, TIME,
    TORQUE, VELOCITY, VOLTAGE, Mode, Register, from_raw, to_raw,
)
from hil.testing import DrivesBench
from test_mit_profile import drive_config

#: can.md "Example": position mode, 3 int16 position registers, a query of 4 int16 and 3
#: int8 registers
DOCUMENT_COMMAND = bytes.fromhex("01000a07206000200150ff140400130d")
DOCUMENT_REPLY = bytes.fromhex("2404000a005000000170ff230d181400")


# --- the document: frames and subframes ------------------------------------------------

class Recorder(multiplex.RegisterServer):
    """A register server that keeps what is written and answers reads with 1 (int) or 1.5."""

    def __init__(self, unknown: frozenset[int] = frozenset()):
        self.written: list[tuple[int, int | float, int]] = []
        self.unknown = unknown

    def write(self, register, raw, kind):
        self.written.append((register, raw, kind))
        return multiplex.UNKNOWN_REGISTER if register in self.unknown else 0

    def read(self, register, kind):
        return None if register in self.unknown else 1.5 if kind == FLOAT else 1


def test_the_documents_example_command_writes_mode_position_velocity_and_torque():
    """can.md "Example": mode 10; 0x020-0x022 as int16: 96 (3.456°), 288 (25.92 dps), -176
    (-1.76 N·m); then reads of 0x000-0x003 (int16) and 0x00d-0x00f (int8)."""
    server = Recorder()
    reply = multiplex.serve(DOCUMENT_COMMAND, server, respond=True)
    assert server.written == [(0x000, 10, INT8), (0x020, 96, INT16), (0x021, 288, INT16),
                              (0x022, -176, INT16)]
    assert from_raw(96, POSITION, INT16) * 360 == pytest.approx(3.456)
    assert from_raw(288, VELOCITY, INT16) * 360 == pytest.approx(25.92)
    assert from_raw(-176, TORQUE, INT16) == pytest.approx(-1.76)
    # the reply's subframes mirror the reads: 0x24 count 4 from 0, 0x23 from 0x00d
    assert reply == bytes.fromhex("240400") + bytes.fromhex("0100") * 4 + bytes.fromhex(
        "230d010101")


def test_the_documents_example_reply_decodes_to_its_annotations():
    """can.md "Example": mode 10, 2.88°, 23.04 dps, -1.44 N·m, 12 V, 20 °C, no fault."""
    values = {}
    for part in multiplex.parse(DOCUMENT_REPLY):
        values.update(part.values)
    assert values == {0x000: 10, 0x001: 80, 0x002: 256, 0x003: -144, 0x00d: 24, 0x00e: 20,
                      0x00f: 0}
    assert from_raw(80, POSITION, INT16) * 360 == pytest.approx(2.88)
    assert from_raw(256, VELOCITY, INT16) * 360 == pytest.approx(23.04)
    assert from_raw(-144, TORQUE, INT16) == pytest.approx(-1.44)
    assert from_raw(24, VOLTAGE, INT8) == 12.0 and from_raw(20, TEMPERATURE, INT8) == 20.0


def test_the_identifier_is_source_destination_and_the_reply_bit():
    """can.md "CAN ID": 0x8001 from 0 to 1, reply requested; 0x100 from 1 to 0; a prefix
    above; extended where the id does not fit 11 bits (fw/fdcan.cc Send)."""
    assert identifier(0, 1, reply=True) == 0x8001
    assert identifier(1, 0) == 0x100
    assert identifier(0, 1, True, prefix=0x10) == 0x108001
    assert moteus_frame(0x100, b"").extended is False
    assert moteus_frame(0x8001, b"").extended is True


def test_frames_are_padded_to_a_can_fd_length_with_nops():
    """can.md "Subframes": trailing padding is NOP (0x50), to a valid CAN FD length."""
    frame = moteus_frame(0x8001, DOCUMENT_COMMAND + b"\x11\x00\x11\x00")
    assert len(frame.data) == 20 and frame.data[16:] == b"\x11\x00\x11\x00"
    frame = moteus_frame(0x8001, bytes(13))
    assert frame.data == bytes(13) + b"\x50" * 3 and frame.fd and frame.bitrate_switch


@pytest.mark.parametrize("scale,lsbs", [
    (POSITION, (0.01, 0.0001, 0.00001)), (VELOCITY, (0.1, 0.00025, 0.00001)),
    (ACCELERATION, (0.05, 0.001, 0.00001)), (TORQUE, (0.5, 0.01, 0.001)),
    (CURRENT, (1.0, 0.1, 0.001)), (TEMPERATURE, (1.0, 0.1, 0.001)),
    (VOLTAGE, (0.5, 0.1, 0.001)), (TIME, (0.01, 0.001, 0.000001)),
    (PWM, (1 / 127, 1 / 32767, 1 / 2147483647)), (POWER, (10.0, 0.05, 0.0001)),
], ids=["position", "velocity", "acceleration", "torque", "current", "temperature",
        "voltage", "time", "pwm", "power"])
def test_each_register_class_maps_integers_as_the_register_reference_says(scale, lsbs):
    """registers.md "Mappings": one LSB per type; the maximally negative integer is NaN
    both ways; a value beyond the type saturates at +-max (fw ScaleSaturate), truncated."""
    for kind, (lsb, limit) in enumerate(zip(lsbs, (127, 32767, 2147483647))):
        assert from_raw(7, scale, kind) == pytest.approx(7 * lsb)
        assert to_raw(7.6 * lsb, scale, kind) == 7
        assert to_raw(-7.6 * lsb, scale, kind) == -7
        assert to_raw(math.nan, scale, kind) == -limit - 1
        assert math.isnan(from_raw(-limit - 1, scale, kind))
        assert to_raw(1e12, scale, kind) == limit and to_raw(-1e12, scale, kind) == -limit
    assert to_raw(0.123, scale, FLOAT) == 0.123 and from_raw(0.5, scale, FLOAT) == 0.5


def test_an_unknown_register_is_a_write_error_and_a_read_error_ends_the_frame():
    """micro_server.cc: a write of an unknown register adds 0x30 (register, 1) and goes on;
    a read that meets one takes its reply subframe back, answers 0x31 (register, 1) and
    drops the rest of the frame."""
    server = Recorder(unknown=frozenset({0x999}))
    data = (multiplex.write(INT8, 0x999, [1]) + multiplex.write(INT8, 0x000, [0])
            + multiplex.read(INT8, 0x998, 2) + multiplex.read(INT8, 0x000, 1))
    reply = multiplex.serve(data, server, respond=True)
    assert [w[0] for w in server.written] == [0x999, 0x000]
    assert reply == bytes([0x30]) + multiplex.varuint(0x999) + b"\x01" + bytes(
        [0x31]) + multiplex.varuint(0x999) + b"\x01"


def test_a_reply_is_cut_to_what_one_can_fd_frame_holds():
    """fw/fdcan_micro_server.h: a reply is at most 64 bytes (``max_size``); hil leaves out
    the reads that would not fit, and a read of a million registers answers nothing."""
    data = multiplex.read(FLOAT, 0x000, 3) * 6 + multiplex.read(FLOAT, 0x000, 1000000)
    reply = multiplex.serve(data, Recorder(), respond=True)
    assert len(reply) == 4 * 14 and moteus_frame(0x100, reply).length == 64


def test_reads_are_answered_only_with_the_reply_bit():
    """micro_server.cc ProcessFrame: a response only where the source's top bit is set."""
    assert multiplex.serve(DOCUMENT_COMMAND, Recorder(), respond=False) == b""


# --- a controller off any bus, lock-step on its own clock ---------------------------------

class Controller:
    """One MoteusDrive (mj5208 on an r4, id 1) at rest at 0; the test hands it frames from
    source 0 and steps its clock (the simulator's watchdog check and after_update at each
    step; the plant stands still)."""

    def __init__(self, watchdog: float = 0.1):
        core = DriveCore(DriveParameters(
            counts_per_rev=1 << 14, rated_torque=0.36, peak_torque=1.6, position_kp=40.0,
            velocity_kp=0.2, velocity_ki=10.0, max_velocity=700.0, following_error_limit=0.0,
            following_error_timeout=0.01, quick_stop_deceleration=500.0,
            watchdog_timeout=watchdog, holding_brake=False))
        core.measure(0.0, 0.0)
        self.drive = MoteusDrive(drive_config(1, "moteus", MoteusOptions()), core,
                                 threading.RLock())
        self.now = 1024.0
        self.drive.clock = lambda: self.now
        self.drive.restart()                     # powered up on the test's clock

    def ask(self, payload: bytes, reply: bool = True, fd: bool = True) -> Frame | None:
        can_id = identifier(0, 1, reply)
        data = multiplex.pad(payload) if fd else payload
        self.drive.on_frame(Frame(can_id, data, can_id > 0x7FF, fd, fd))
        replies = self.drive.take_replies()
        return replies[0] if replies else None

    def values(self, payload: bytes) -> dict[int, float]:
        found = {}
        for part in multiplex.parse(self.ask(payload).data):
            if isinstance(part, multiplex.Values):
                found.update(part.values)
        return found

    def mode(self) -> int:
        return self.values(multiplex.read(INT8, Register.MODE, 1))[Register.MODE]

    def wait(self, seconds: float, step: float = 0.002) -> None:
        for _ in range(round(seconds / step)):
            self.now += step
            self.drive.core.check_watchdog(self.now)
            self.drive.after_update()


def test_the_reply_goes_from_the_controller_to_the_asker_as_fd_with_brs_as_asked():
    """fw/fdcan_micro_server.h AsyncWrite: id (own << 8) | asker; FD where the request was
    FD or the reply is longer than 8 bytes; BRS as the request had it; NOP padding."""
    motor = Controller()
    reply = motor.ask(DOCUMENT_COMMAND[3:])
    assert reply.identifier == 0x100 and not reply.extended
    assert reply.fd and reply.bitrate_switch and len(reply.data) == 16
    short = motor.ask(multiplex.read(INT8, Register.MODE, 1), fd=False)
    assert not short.fd and bytes(short.data) == bytes([0x21, 0x00, 0x00])
    assert motor.ask(multiplex.read(INT8, Register.MODE, 1), reply=False) is None


def test_mode_group_position_mode_stop_and_an_unwritable_mode():
    """registers.md 0x000: written first, 10 position, 0 stopped; fw Write: a mode past the
    last (15) is an unknown register (write error on 0x000)."""
    motor = Controller()
    assert motor.mode() == Mode.STOPPED
    motor.ask(position_command(0.0, 0.0, 0.0))
    assert motor.mode() == Mode.POSITION
    answer = motor.ask(multiplex.write(INT8, Register.MODE, [16]))
    assert bytes(answer.data[:3]) == bytes([0x30, 0x00, 0x01])
    assert motor.mode() == Mode.POSITION
    motor.ask(multiplex.write(INT8, Register.MODE, [Mode.STOPPED]))
    assert motor.mode() == Mode.STOPPED


def test_a_frames_reads_report_the_state_before_its_command():
    """fw: the reads are served while the frame is parsed, the command applied after it
    (moteus_controller.cc Poll)."""
    motor = Controller()
    before = motor.values(multiplex.write(INT8, Register.MODE, [Mode.POSITION])
                          + multiplex.read(INT8, Register.MODE, 1))
    assert before[Register.MODE] == Mode.STOPPED and motor.mode() == Mode.POSITION


def test_position_command_group_reads_back_with_its_defaults():
    """registers.md 0x020-0x02d; a mode write starts the command from CommandData's
    defaults (kp/kd scale 1, max torque 100 N·m, limits NaN, watchdog 0); 0x043 shadows
    0x023."""
    motor = Controller()
    motor.ask(position_command(0.5, 0.25, 0.1) + multiplex.write(FLOAT, Register.KD_SCALE,
                                                                 [0.5]))
    values = motor.values(multiplex.read(FLOAT, Register.COMMAND_POSITION, 10)
                          + multiplex.read(FLOAT, 0x043, 1))
    assert [values[r] for r in range(0x020, 0x026)] == pytest.approx(
        [0.5, 0.25, 0.1, 1.0, 0.5, 100.0])
    assert math.isnan(values[0x026]) and values[0x027] == 0.0
    assert math.isnan(values[0x028]) and math.isnan(values[0x029]) and values[0x043] == 1.0


def test_kp_and_kd_scale_and_the_maximum_torque_shape_the_command():
    """registers.md 0x023/0x024 scale the gains (kd no more than kp's scale), 0x025 caps
    the torque; the gains are servo.pid_position's, per revolution (4.0, 0.05)."""
    motor = Controller()
    core, turn = motor.drive.core, 2 * math.pi
    core.measure(0.0, -1.0)                              # rad/s
    motor.ask(position_command(0.0, 0.0, 0.0) + multiplex.write(
        FLOAT, Register.KP_SCALE, [0.5, 0.8]))
    assert core.update(0.001) == pytest.approx(0.05 * 0.5 / turn)          # kd x 0.5, not 0.8
    core.measure(0.0, 0.0)
    motor.ask(position_command(0.1, 0.0, 0.0) + multiplex.write(
        FLOAT, Register.KP_SCALE, [0.5, 0.8, 0.15]))
    assert core.update(0.001) == pytest.approx(0.15)     # 4 x 0.5 x 0.1 = 0.2 N·m, capped


@pytest.mark.parametrize("register", range(0x020, 0x026), ids=lambda r: f"0x{r:03x}")
def test_a_non_finite_command_value_applies_no_torque_at_rest(register):
    """Bad input: NaN or infinity in a position register of a controller at rest at its
    target gives no torque (registers.md's NaN meanings; elsewhere the default, hil's)."""
    for value in (math.nan, math.inf, -math.inf):
        motor = Controller()
        motor.ask(position_command(0.0, 0.0, 0.0) + multiplex.write(FLOAT, register, [value]))
        assert motor.drive.core.update(0.001) == 0.0


def test_query_group_answers_the_librarys_default_registers():
    """moteus.QueryResolution: mode, position, velocity, torque (0x000-0x003), voltage,
    temperature, fault (0x00d-0x00f); at rest, stopped, 24 V, 25 °C, no fault."""
    values = Controller().values(multiplex.read(INT8, Register.MODE, 1)
                                 + multiplex.read(FLOAT, Register.POSITION, 3)
                                 + multiplex.read(INT8, Register.VOLTAGE, 3))
    assert values == {0x000: 0, 0x001: 0.0, 0x002: 0.0, 0x003: 0.0, 0x00d: 48, 0x00e: 25,
                      0x00f: 0}


def test_read_only_registers_refuse_writes_and_unserved_ones_read_as_unknown():
    """fw Write: kNotWriteable (2) for a measured value; Read of a register hil does not
    simulate: error 1, as the firmware answers a register it does not know."""
    motor = Controller()
    answer = motor.ask(multiplex.write(FLOAT, Register.POSITION, [1.0]))
    assert bytes(answer.data[:3]) == bytes([0x30, 0x01, 0x02])
    answer = motor.ask(multiplex.read(FLOAT, 0x050, 1))      # encoder 0: not simulated
    assert bytes(answer.data) == bytes([0x31, 0x50, 0x01])
    assert motor.values(multiplex.read(INT32, Register.REGISTER_MAP_VERSION, 1)) == {
        0x102: 5}


def test_the_millisecond_counter_wraps_at_the_queried_type():
    """registers.md 0x070: wraps at the type's maximum to its minimum (fw Read: the counter
    cast to int8/int16/int32, as float modulo 2^23)."""
    motor = Controller()
    motor.now += 0.5                                    # 500 ms (exact in binary)
    read = (multiplex.read(INT8, Register.MILLISECOND_COUNTER, 1)
            + multiplex.read(INT16, Register.MILLISECOND_COUNTER, 1))
    values = {}
    for part in multiplex.parse(motor.ask(read).data):
        values[part.kind] = part.values[Register.MILLISECOND_COUNTER]
    assert values == {INT8: 500 % 256 - 256, INT16: 500}


def test_set_output_exact_and_nearest_move_the_reported_position_only():
    """registers.md 0x130/0x131: the output reads the given position (exact), or the whole
    turns closest to it (nearest); home state 2 after either."""
    motor = Controller()
    motor.ask(multiplex.write(FLOAT, Register.SET_OUTPUT_EXACT, [0.3]))
    read = multiplex.read(FLOAT, Register.POSITION, 1) + multiplex.read(INT8, 0x00C, 1)
    assert motor.values(read) == {0x001: pytest.approx(0.3), 0x00C: 2}
    motor.ask(multiplex.write(FLOAT, Register.SET_OUTPUT_NEAREST, [5.1]))
    assert motor.values(read)[0x001] == pytest.approx(5.3)


def test_silence_past_the_watchdog_is_position_timeout_until_a_stop():
    """registers.md 0x027 and configuration.md servo.default_timeout_s: no command within
    the timeout puts position mode in 11, position timeout; fw ISR_MaybeChangeMode: only a
    stop leaves it, a position command meanwhile changes nothing."""
    motor = Controller(watchdog=0.1)
    motor.ask(position_command(0.0, 0.0, 0.0))
    motor.wait(0.05)
    motor.ask(position_command(0.0, 0.0, 0.0))          # fed: still in time
    motor.wait(0.08)
    assert motor.mode() == Mode.POSITION                 # a query does not feed it
    motor.wait(0.04)
    assert motor.mode() == Mode.POSITION_TIMEOUT
    motor.ask(position_command(0.2, 0.0, 0.0))
    assert motor.mode() == Mode.POSITION_TIMEOUT
    motor.ask(multiplex.write(INT8, Register.MODE, [Mode.STOPPED]))
    motor.ask(position_command(0.2, 0.0, 0.0))
    assert motor.mode() == Mode.POSITION


def test_the_commands_own_watchdog_overrides_and_nan_turns_it_off():
    """registers.md 0x027: the command's timeout, 0 the configured default, NaN none."""
    motor = Controller(watchdog=0.1)
    motor.ask(position_command(0.0, 0.0, 0.0)
              + multiplex.write(FLOAT, Register.WATCHDOG_TIMEOUT, [0.5]))
    motor.wait(0.3)
    assert motor.mode() == Mode.POSITION
    motor.ask(position_command(0.0, 0.0, 0.0)
              + multiplex.write(FLOAT, Register.WATCHDOG_TIMEOUT, [math.nan]))
    motor.wait(2.0)
    assert motor.mode() == Mode.POSITION


def test_a_fault_is_mode_1_with_its_code_until_a_stop():
    """registers.md 0x00f: the code is set while the mode is 1 (fault); a stop clears it."""
    from hil.drives.definitions import Fault

    motor = Controller()
    motor.ask(position_command(0.0, 0.0, 0.0))
    motor.drive.core.raise_fault(Fault.POSITION_LIMIT)
    motor.drive.after_update()
    read = multiplex.read(INT8, Register.MODE, 1) + multiplex.read(INT8, Register.FAULT, 1)
    assert motor.values(read) == {0x000: 1, 0x00f: 39}
    motor.ask(multiplex.write(INT8, Register.MODE, [Mode.STOPPED]))
    assert motor.values(read) == {0x000: 0, 0x00f: 0}


# --- the protocol's description: models, options, the bus -------------------------------

def test_models_carry_the_makers_controller_currents_and_motor_figures():
    """docs/reference/hardware.md peak outputs; docs/mpat.html's mj5208: Kv 304, 14 poles."""
    assert {n: c.peak_current for n, c in CONTROLLERS.items()} == {
        "r4": 100.0, "c1": 20.0, "n1": 100.0, "x1": 120.0}
    mj5208 = MOTORS["mj5208"]
    assert (mj5208.kv, mj5208.pole_pairs) == (304, 7)
    assert MODELS["mj5208"].peak_torque == pytest.approx(1.64, abs=0.01)
    options = MoteusOptions.from_mapping({"motor": "MJ5208", "controller": "moteus-c1"})
    assert options.drive_defaults()["peak_torque"] == pytest.approx(mj5208.torque(20.0))
    with pytest.raises(ValueError, match="no moteus controller 'r9'"):
        MoteusOptions.from_mapping({"controller": "r9"})


def test_a_classical_bus_is_refused_naming_bus_and_node(tmp_path):
    """can.md "CAN Format": moteus speaks CAN FD only."""
    path = one_axis(tmp_path, 0.1, fd=False)
    with pytest.raises(HilError) as refused:
        load_bus_config(path)
    assert "bus 'arm'" in str(refused.value) and "node 1" in str(refused.value)
    assert "fd: true" in str(refused.value)


def test_frame_source_tells_commands_from_replies():
    drives = {1: None}
    assert Moteus.frame_source(Frame(0x8001, b""), drives).sender.value == "master"
    assert Moteus.frame_source(Frame(0x100, b""), drives).sender.value == "drive"
    assert Moteus.frame_source(Frame(0x8002, b""), drives) is None


def one_axis(tmp_path, watchdog: float, fd: bool = True) -> str:
    """A moteus (mj5208, r4) on the Damiao tests' disc, on a CAN FD bus (1 Mbit/s, 5 Mbit/s
    data, can.md's)."""
    path = tmp_path / "moteus.yaml"
    path.write_text(f"""\
robot: {TESTS / 'fixtures' / 'damiao_one_axis.urdf'}
transmissions:
  yaw: {{reduction: 1, rotor_inertia: 0.000056}}
defaults: {{protocol: moteus, watchdog_timeout: {watchdog}}}
buses:
  - name: arm
    interface: zenoh
    channel: moteus/arm
    cycle_hz: 500
    fd: {'true' if fd else 'false'}
    drives:
      - {{node_id: 1, joint: yaw, options: {{motor: mj5208, kp: 4.0, kd: 0.2}}}}
""")
    return str(path)


def test_hil_init_writes_a_moteus_config(tmp_path):
    from hil.cli import main

    output = tmp_path / "one.yaml"
    assert main(["init", str(TESTS / "fixtures" / "damiao_one_axis.urdf"), "--protocol",
                 "moteus", "-o", str(output)]) == 0
    config = load_bus_config(output)
    drive = config.drives[0]
    assert config.buses[0].fd                   # moteus has no place on a classical bus
    assert drive.protocol == "moteus" and drive.options.motor.name in MOTORS
    assert drive.options.kp > 0 and drive.holding_brake is False
    assert protocol("moteus") is Moteus


def test_hils_master_drives_a_moteus_lock_step(tmp_path):
    from hil.controllers import GoalStatus

    result, position = hils_master_moves(one_axis(tmp_path, 0.5), "yaw", 0.5)
    assert result.status is GoalStatus.SUCCEEDED, result
    assert position == pytest.approx(0.5, abs=0.01)


# --- the maker's library: moteus.Controller over moteus.PythonCan -------------------------

def library_run(bench: DrivesBench, steps) -> None:
    """``steps(controller)`` with a ``moteus.Controller(id=1)`` on ``moteus.PythonCan`` over
    the bench's bus (python-can ``virtual``; the library opens it with ``fd=True``)."""
    import moteus

    async def main():
        transport = moteus.PythonCan(interface="virtual", channel=bench.channel("arm"))
        try:
            await asyncio.wait_for(steps(moteus.Controller(id=1, transport=transport)), 60)
        finally:
            transport.close()

    asyncio.run(main())


def test_the_moteus_library_queries_moves_and_stops_a_controller(tmp_path):
    """python.md "Basic Usage": Controller(id=1), query(), set_position(..., query=True) in
    a loop, set_stop(); lock-step, each of its queries one cycle of the plant. The watchdog
    off (0) so that the host's pace cannot trip it."""
    import moteus

    with DrivesBench(one_axis(tmp_path, 0.0), lock_step=True) as bench:
        seen = {}

        async def steps(controller):
            seen["query"] = (await controller.query()).values
            for _ in range(750):                   # 1.5 s of plant time at 500 Hz
                result = await controller.set_position(position=0.25, velocity=0.0,
                                                       query=True)
            seen["moved"] = result.values
            await controller.set_stop()
            seen["stopped"] = (await controller.query()).values

        library_run(bench, steps)
        query, moved, stopped = seen["query"], seen["moved"], seen["stopped"]
        assert query[moteus.Register.MODE] == 0 and query[moteus.Register.FAULT] == 0
        assert query[moteus.Register.VOLTAGE] == 24.0
        assert moved[moteus.Register.MODE] == 10
        assert moved[moteus.Register.POSITION] == pytest.approx(0.25, abs=0.002)
        assert bench.joint("yaw") == pytest.approx(0.25 * 2 * math.pi, abs=0.02)
        assert stopped[moteus.Register.MODE] == 0


def test_the_moteus_library_sees_the_position_timeout_and_stops_out_of_it(tmp_path):
    """registers.md 0x027 through the library's ``watchdog_timeout``: silent past it, mode
    11; only set_stop leaves it. The silence is the controller's clock moved on, not a
    sleep (the simulator's own check runs on the wall clock)."""
    import moteus

    with DrivesBench(one_axis(tmp_path, 0.0), lock_step=True) as bench:
        drive = bench.sim.drives[0]
        # the controller's clock ahead of the wall clock's: the simulator's own check (on
        # time.monotonic) sees no silence, the test's moves it on
        now = [time.monotonic() + 1e6]
        drive.clock = lambda: now[0]
        seen = {}

        def silence(seconds: float) -> None:
            with bench.sim.lock:
                now[0] += seconds
                drive.core.check_watchdog(now[0])
                drive.after_update()

        async def steps(controller):
            await controller.set_position(position=0.0, watchdog_timeout=0.2, query=True)
            silence(0.1)
            seen["fed"] = (await controller.query()).values[moteus.Register.MODE]
            silence(0.3)
            seen["silent"] = (await controller.query()).values[moteus.Register.MODE]
            await controller.set_position(position=0.1, query=True)
            seen["ignored"] = (await controller.query()).values[moteus.Register.MODE]
            await controller.set_stop()
            await controller.set_position(position=0.0, query=True)
            seen["again"] = (await controller.query()).values[moteus.Register.MODE]

        library_run(bench, steps)
        assert seen == {"fed": 10, "silent": 11, "ignored": 11, "again": 10}


def test_the_library_sends_fd_frames_with_brs_and_gets_them_back(tmp_path):
    """The library's frames (transport.py ``_command_to_frame``: is_fd, bitrate_switch) and
    the controller's reply as the bus carries them: FD, BRS, padded with 0x50."""
    with DrivesBench(one_axis(tmp_path, 0.0)) as bench:
        bus = bench.bus("arm")
        bus.send(can.Message(arbitration_id=0x8001, data=DOCUMENT_COMMAND, is_fd=True,
                             bitrate_switch=True, is_extended_id=True))
        deadline = time.monotonic() + 10
        reply = None
        while reply is None and time.monotonic() < deadline:
            reply = bus.recv(1.0)
        assert reply is not None and reply.arbitration_id == 0x100
        assert reply.is_fd and reply.bitrate_switch and len(reply.data) == 16
        assert bytes(reply.data[:3]) == bytes.fromhex("240400")
