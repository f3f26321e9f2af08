"""Damiao DM-J motors on CAN FD, as the maker's FD firmware and OpenArm run them: the rate
codes of CAN_BR (register 35), the frames the motor answers with (FD with the bit-rate
switch, DLC 8, registers included), the frames it takes (classic, FD with and without BRS),
a frame whose format is not the motor's (reported once, naming bus and node), and hil's own
master sending FD frames with BRS on an FD bus.

Sources: the DM4310's firmware as recovered in github.com/umeow0716/damiao_firmware
(board/src/board_mcan_config.c: the data-phase timings by CAN_BR code, 80 MHz MCAN clock;
board/src/board_mcan_hc32f448.c: ``board_mcan_send_fd_payload``'s Tx element flags FDF|BRS,
``board_mcan_receive_payload`` reading no FDF or BRS); openarm_can's frames
(src/openarm/damiao_motor/dm_motor_device.cpp ``create_canfd_frame``: ``flags = CANFD_BRS``,
``len`` 8); enactic/openarm_teleop #8 (a motor left classic on an FD bus answers an FD frame
with a classic one); LeRobot 0.4.4's ``can.Message(..., is_fd=True)`` without
``bitrate_switch`` (huggingface/lerobot #3178)."""

from __future__ import annotations

import logging
import struct
from pathlib import Path

import can
import pytest

from conftest import TESTS, hils_master_moves
from hil.bus_config import load_bus_config
from hil.controllers import GoalStatus
from hil.errors import ConfigError
from hil.hardware.axis import AxisCommand
from hil.protocols.damiao import DISABLE, ENABLE, REGISTER_ID, DamiaoOptions, Op, State
from hil.protocols.damiao.axis import DamiaoAxis
from hil.protocols.damiao.fd import FD_CODES, rate_code
from hil.protocols.mit import frame_on_bus
from hil.testing import DrivesBench

URDF = TESTS / "fixtures" / "damiao_one_axis.urdf"
#: the DM4310's MCAN clock (Hz) and its data-phase timing by CAN_BR code: (prescaler,
#: seg1, seg2), board_mcan_config.c ``data_timing_for_selector``; a bit is 1 + seg1 + seg2
#: time quanta (``board_mcan_current_data_rate_kbps``: (seg1 - 1) + (seg2 - 1) + 3)
MCAN_CLOCK = 80e6
DATA_TIMINGS = {5: (1, 31, 8), 6: (1, 25, 6), 7: (1, 19, 5), 8: (1, 15, 4), 9: (1, 12, 3),
                10: (1, 7, 2), 11: (1, 5, 2)}


def one_axis(tmp_path, bus: str, options: str = "") -> DrivesBench:
    """A lock-step bench of :func:`write_config`'s."""
    return DrivesBench(write_config(tmp_path, bus, options), lock_step=True)


def write_config(tmp_path, bus: str, options: str = "") -> Path:
    """A bus config of one DM4310 (node 1, master id 0x11) on bus ``arm`` with the bus keys
    ``bus`` and the drive's extra ``options``."""
    path = tmp_path / "damiao_fd.yaml"
    path.write_text(f"""robot: {URDF}
transmissions:
  yaw: {{reduction: 1, rotor_inertia: 0.0018}}
defaults: {{protocol: damiao}}
buses:
  - name: arm
    interface: zenoh
    channel: damiao/fd
    cycle_hz: 500
    {bus}
    drives:
      - {{node_id: 1, joint: yaw,
         options: {{model: DM4310, master_id: 0x11, kp: 5.0, kd: 0.3{options}}}}}
""")
    return path


FD_BUS = "bitrate: 1000000\n    fd: true\n    data_bitrate: 5000000"
CLASSIC_BUS = "bitrate: 1000000"


def reports(caplog) -> list[str]:
    """What hil.protocols.damiao.fd logged."""
    return [r.getMessage() for r in caplog.records if r.name == "hil.protocols.damiao.fd"]


class Master:
    """A master's python-can bus on the bench: a frame sent, the cycle closed, the answer."""

    def __init__(self, bench: DrivesBench):
        self.bench, self.bus = bench, bench.bus()

    def ask(self, can_id: int, data: bytes, fd: bool = True, brs: bool = True
            ) -> can.Message | None:
        self.bus.send(can.Message(arbitration_id=can_id, data=data, is_extended_id=False,
                                  is_fd=fd, bitrate_switch=brs))
        self.bench.step()
        return self.bus.recv(0)


@pytest.fixture
def fd_motor(tmp_path):
    with one_axis(tmp_path, FD_BUS) as bench:
        yield Master(bench)


# --- the codes and frames, against the sources ---------------------------------------------

def test_can_br_codes_are_the_firmwares_data_rates():
    for code, (prescaler, seg1, seg2) in DATA_TIMINGS.items():
        data_rate = MCAN_CLOCK / (prescaler * (1 + seg1 + seg2))
        assert FD_CODES[round(data_rate)] == code
    assert rate_code(1_000_000, True, 5_000_000) == 9              # OpenArm's 1M/5M
    assert rate_code(1_000_000, False, None) == 4                   # the factory's 1M


def test_a_bus_no_dm_motor_runs_is_refused_naming_the_rates():
    with pytest.raises(ValueError, match="1000000 bit/s nominal and .*5000000.* not 1000000 "
                                         "and 6000000"):
        rate_code(1_000_000, True, 6_000_000)
    with pytest.raises(ValueError, match="not 2000000"):
        rate_code(2_000_000, False, None)


def test_an_fd_answer_is_8_bytes_with_brs_and_a_classic_one_neither():
    feedback = bytes(range(8))
    fd = frame_on_bus(0x11, feedback, True)
    assert (fd.fd, fd.bitrate_switch, fd.data, fd.problem()) == (True, True, feedback, None)
    classic = frame_on_bus(0x11, feedback, False)
    assert (classic.fd, classic.bitrate_switch) == (False, False)


def test_options_take_can_br_and_refuse_a_code_the_firmware_has_not():
    assert DamiaoOptions.from_mapping({"can_br": 9}).can_br == 9
    assert DamiaoOptions.from_mapping({}).can_br is None
    with pytest.raises(ValueError, match="'can_br' 12 is not a rate code 0-11"):
        DamiaoOptions.from_mapping({"can_br": 12})


# --- a motor on an FD bus ---------------------------------------------------------------------

def test_on_an_fd_bus_every_answer_is_fd_with_brs_and_8_bytes(fd_motor):
    """openarm_can's enable (FF x 7 FC, FD with BRS, len 8) is answered on the master's id
    in an FD frame with BRS (the firmware's FD send: FDF|BRS, DLC the payload's 8)."""
    reply = fd_motor.ask(0x001, ENABLE)
    assert reply is not None and reply.arbitration_id == 0x11
    assert (reply.is_fd, reply.bitrate_switch, len(reply.data)) == (True, True, 8)
    assert reply.data[0] == (State.ENABLED << 4) | 1


def test_register_answers_are_fd_and_can_br_reads_the_buses_code(fd_motor):
    """openarm_can's query (0x7FF: id lo, id hi, 0x33, RID) of CAN_BR, as its motor-check
    prints "Queried Baudrate": 9 on a 1M/5M bus, answered in FD with BRS."""
    reply = fd_motor.ask(REGISTER_ID, bytes([1, 0, Op.READ, 35, 0, 0, 0, 0]))
    assert reply is not None and (reply.is_fd, reply.bitrate_switch) == (True, True)
    assert struct.unpack_from("<I", reply.data, 4)[0] == 9


def test_lerobots_fd_frames_without_brs_are_taken_and_answered_with_brs(fd_motor, caplog):
    """LeRobot 0.4.4 sends FD frames without BRS (lerobot #3178): the firmware's receive path
    reads neither flag, so they move the motor as any other; the answer has BRS."""
    with caplog.at_level(logging.WARNING):
        reply = fd_motor.ask(0x001, ENABLE, brs=False)
        refresh = fd_motor.ask(REGISTER_ID, bytes([1, 0, Op.REFRESH, 0, 0, 0, 0, 0]), brs=False)
    assert reply.data[0] >> 4 == State.ENABLED and reply.bitrate_switch
    assert refresh is not None and refresh.arbitration_id == 0x11 and refresh.is_fd
    assert not reports(caplog)                      # nothing the motor does not take


def test_a_classic_frame_to_an_fd_motor_is_answered_in_fd_and_reported_once(fd_motor, caplog):
    with caplog.at_level(logging.WARNING):
        first = fd_motor.ask(0x001, ENABLE, fd=False, brs=False)
        fd_motor.ask(0x001, DISABLE, fd=False, brs=False)
    assert first.is_fd and first.bitrate_switch
    assert first.data[0] >> 4 == State.ENABLED
    [report] = reports(caplog)
    assert "bus 'arm' node 1: a classic CAN frame" in report and "fd=True" in report


def test_a_can_br_write_switches_the_answers_format_at_once(fd_motor):
    """The firmware swaps its send function on a CAN_BR write without restarting the MCAN
    (board_mcan_hc32f448.c ``select_transport_format``): from the write's answer on, a
    classic code answers classic."""
    write = fd_motor.ask(REGISTER_ID, bytes([1, 0, Op.WRITE, 35]) + struct.pack("<I", 4))
    assert write is not None and not write.is_fd
    assert struct.unpack_from("<I", write.data, 4)[0] == 4
    assert not fd_motor.ask(0x001, ENABLE).is_fd


def test_a_motor_left_classic_on_an_fd_bus_answers_classic_and_is_reported(tmp_path, caplog):
    """enactic/openarm_teleop #8: on a 1M/5M FD bus, `cansend can0 001##1.FF..FD` was
    answered by a classic frame: the motor's CAN_BR was classic. A master reading FD frames
    only (openarm_can with enable_fd) misses it; the log says so, naming bus and node."""
    with one_axis(tmp_path, FD_BUS, ", can_br: 4") as bench, caplog.at_level(logging.WARNING):
        reply = Master(bench).ask(0x001, DISABLE)
    assert reply is not None and (reply.is_fd, reply.arbitration_id) == (False, 0x11)
    [report] = reports(caplog)
    assert "bus 'arm' node 1: a CAN FD frame" in report and "leave 'can_br' out" in report


def test_openarm_cans_4_byte_velocity_command_drives_the_motor(tmp_path):
    """openarm_can sends the velocity command as 4 bytes (dm_motor_control.cpp
    ``pack_vel_control_data``: D0-D3 the float, "Velocity mode frame") in an FD frame of
    len 4; the firmware reads 8 bytes of any frame (``board_mcan_receive_payload``), the
    velocity from the first 4. hil refused every frame but an 8-byte one."""
    with one_axis(tmp_path, FD_BUS, ", control_mode: velocity") as bench:
        master = Master(bench)
        master.ask(0x001, ENABLE)
        master.ask(0x201, struct.pack("<h", 1))            # 2 bytes: no velocity
        assert bench.sim.drives[0].malformed == 1
        reply = master.ask(0x201, struct.pack("<f", 2.0))
        bench.step(100)                                     # 0.2 s
        assert reply is not None and reply.is_fd
        assert bench.sim.drives[0].malformed == 1
        assert bench.joint("yaw") > 0.2


def test_on_a_classic_bus_the_motor_answers_classic(tmp_path):
    with one_axis(tmp_path, CLASSIC_BUS) as bench:
        reply = Master(bench).ask(0x001, ENABLE, fd=False, brs=False)
    assert reply is not None and not reply.is_fd and not reply.bitrate_switch


def test_a_bus_whose_rates_no_dm_motor_runs_is_a_config_error(tmp_path):
    bus = "bitrate: 1000000\n    fd: true\n    data_bitrate: 6000000"
    with pytest.raises(ConfigError, match="bus 'arm' drive node 1: a DM-J motor runs CAN FD"):
        one_axis(tmp_path, bus).close()


# --- hil's own master ---------------------------------------------------------------------------

@pytest.mark.parametrize("bus_text, fd", [(FD_BUS, True), (CLASSIC_BUS, False)],
                         ids=["fd", "classic"])
def test_hils_master_sends_fd_frames_with_brs_on_an_fd_bus_classic_ones_on_a_classic(
        tmp_path, bus_text, fd):
    bus = load_bus_config(write_config(tmp_path, bus_text)).buses[0]
    axis = DamiaoAxis(bus.drives[0], bus.name)
    frames = [*axis.disable_rounds()[0], *axis.cycle_frames(AxisCommand(0.0, 0.0))]
    assert all(frame.fd is fd and frame.bitrate_switch is fd and frame.length == 8
               and frame.identifier == bus.drives[0].node_id for frame in frames)


def test_hils_master_moves_a_motor_over_can_fd_lock_step(tmp_path):
    result, position = hils_master_moves(write_config(tmp_path, FD_BUS), "yaw", 0.5)
    assert result.status is GoalStatus.SUCCEEDED, result
    assert position == pytest.approx(0.5, abs=0.01)

