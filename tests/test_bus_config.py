"""Bus configs: typed parsing, validation against the robot, bus-load feasibility."""

from __future__ import annotations

import pytest

from hil.bus_config import check_together, load_bus_config
from hil.can import frame_bits
from hil.cli import main
from hil.errors import HilError
from conftest import ROOT

UR3 = "robots/ur3_description/urdf/ur3.xacro"


def write_config(tmp_path, body: str):
    path = tmp_path / "bench.yaml"
    path.write_text(f"robot: {ROOT / UR3}\n" + body)
    return path


def one_bus(drives: str, cycle_hz=500, bitrate=1000000) -> str:
    lines = "".join(f"      {line}\n" for line in drives.splitlines())
    return ("buses:\n  - name: arm\n    interface: virtual\n    channel: test\n"
            f"    bitrate: {bitrate}\n    cycle_hz: {cycle_hz}\n    drives:\n{lines}")


ALL_SIX = "".join(f"- {{node_id: {i}, joint: joint{i}}}\n" for i in range(1, 7))


def errors_of(path):
    with pytest.raises(HilError) as caught:
        load_bus_config(path)
    return caught.value.diagnostics


@pytest.mark.parametrize("name", ["ur3.yaml", "ur3_1khz.yaml", "pigot.yaml", "pigot_mixed.yaml",
                                  "openarm.yaml"])
def test_shipped_configs_load_and_check(name, capsys):
    config = load_bus_config(ROOT / "bus_config" / name)
    assert all(bus.load().worst_ratio <= 1.0 for bus in config.buses)
    assert {d.actuator for d in config.drives} == {a.name for a in config.robot.actuators}
    assert main(["check", str(ROOT / "bus_config" / name)]) == 0
    assert "worst case" in capsys.readouterr().out


def test_frame_bits_match_can_arithmetic():
    assert frame_bits(8) == (111, 135)
    assert frame_bits(0) == (47, 55)
    assert frame_bits(6) == (95, 115)
    assert frame_bits(8, extended=True) == (131, 160)


def test_seven_drives_at_1khz_on_one_bus_is_rejected_with_numbers(tmp_path):
    drives = ALL_SIX + "- {node_id: 7, joint: joint6}\n"
    (diag, *_) = [d for d in errors_of(write_config(tmp_path, one_bus(drives, 1000)))
                  if "infeasible" in d.message]
    assert "7 drive(s) at 1000 Hz need 2,475 kbit/s worst case" in diag.message
    assert "1,000 kbit/s bus: 247%" in diag.message
    assert "split the drives over buses of at most" in diag.hint and "cycle_hz" in diag.hint


def test_six_drives_at_1khz_is_infeasible_but_at_250hz_fits(tmp_path):
    assert any("infeasible" in d.message for d in
               errors_of(write_config(tmp_path, one_bus(ALL_SIX, 1000))))
    config = load_bus_config(write_config(tmp_path, one_bus(ALL_SIX, 250)))
    assert config.buses[0].load().worst_ratio == pytest.approx(0.53, abs=0.01)


def test_velocity_feed_forward_adds_each_drives_rpdo4_to_the_bus_load(tmp_path):
    plain = load_bus_config(write_config(tmp_path, one_bus(ALL_SIX, 250)))
    fed = load_bus_config(write_config(tmp_path, one_bus(
        ALL_SIX.replace("}", ", options: {feed_forward: velocity}}"), 250)))
    assert all(d.options.feed_forward == "velocity" for d in fed.drives)
    # six drives, each one 6-byte frame (0x500 + id) more per cycle
    extra = 6 * 250 * frame_bits(6)[1] / 1_000_000
    assert fed.buses[0].load().worst_ratio == pytest.approx(
        plain.buses[0].load().worst_ratio + extra)


def test_actuator_effects_are_read_per_drive_over_the_defaults_and_off_unless_set(tmp_path):
    body = ("defaults:\n  effects: {viscous_friction: 0.001}\n"
            + one_bus(ALL_SIX.replace("joint: joint1}", "joint: joint1, effects: "
                                      "{coulomb_friction: 0.02, delay: 0.002}}"), 250))
    config = load_bus_config(write_config(tmp_path, body))
    first, second = config.drives[:2]
    assert first.effects.in_force() == {"coulomb_friction": 0.02, "delay": 0.002}
    assert second.effects.in_force() == {"viscous_friction": 0.001}
    assert set(config.effects) == {d.actuator for d in config.drives}
    plain = load_bus_config(write_config(tmp_path, one_bus(ALL_SIX, 250)))
    assert plain.effects == {} and not plain.drives[0].effects.in_force()


def test_heavy_but_feasible_load_warns(tmp_path):
    config = load_bus_config(write_config(tmp_path, one_bus(ALL_SIX, 250, bitrate=625000)))
    (warning,) = config.warnings
    assert "above 80%" in warning.message


@pytest.mark.parametrize("drives, message", [
    (ALL_SIX.replace("node_id: 2,", "node_id: 1,"), "node id 1 is used by"),
    (ALL_SIX.replace("node_id: 3,", "node_id: 130,"), "node id 130 is outside 1..127"),
    (ALL_SIX.replace("joint: joint4", "joint: joint9"), "joint 'joint9' does not exist"),
    (ALL_SIX.replace("- {node_id: 6, joint: joint6}\n", ""), "actuator 'joint6_motor' (joint "
                                                             "joint6) has no drive"),
    (ALL_SIX.replace("joint: joint5}", "joint: joint5, protocol: canfd402}"),
     "unknown protocol 'canfd402'"),
    (ALL_SIX.replace("joint: joint1}", "joint: joint1, peak_torque: -1}"),
     "'peak_torque' must be > 0"),
    (ALL_SIX.replace("joint: joint1}", "joint: joint1, gian: 3}"), "unknown key 'gian'"),
    (ALL_SIX.replace("node_id: 6, joint: joint6}", "node_id: 64, joint: joint6, protocol: odrive}"),
     "node id 64 is outside 0..62"),
    (ALL_SIX.replace("joint: joint6}", "joint: joint6, protocol: mit}"), "options: 'kp' must be"),
    (ALL_SIX.replace("joint: joint6}", "joint: joint6, protocol: mit, options: {kp: 1, kq: 2}}"),
     "unknown option(s) kq for protocol 'mit'"),
    (ALL_SIX.replace("joint: joint6}", "joint: joint6, options: {kp: 1}}"),
     "unknown option(s) kp for protocol 'cia402'"),
    (ALL_SIX.replace("joint: joint6}", "joint: joint6, options: {feed_forward: torque}}"),
     "'feed_forward' is one of none, velocity, not 'torque'"),
    (ALL_SIX.replace("joint: joint2}", "joint: joint2, effects: {cogging: 0.01}}"),
     "unknown key 'cogging'"),
    (ALL_SIX.replace("joint: joint2}", "joint: joint2, effects: {delay: -0.001}}"),
     "effects: 'delay' must be >= 0 (0: off), not -0.001"),
    # issue 64: a misspelt name is answered with the closest known one (difflib's, as
    # Python's own NameError suggests one), not the whole list alone
    (ALL_SIX.replace("joint: joint1}", "joint: joint1, rated_torqe: 3}"),
     "unknown key 'rated_torqe' in bus 'arm' drive (did you mean 'rated_torque'?)"),
    (ALL_SIX.replace("joint: joint5}", "joint: joint5, protocol: odrve}"),
     "unknown protocol 'odrve' (did you mean 'odrive'?)"),
    (ALL_SIX.replace("joint: joint4", "joint: jiont4"),
     "joint 'jiont4' does not exist in robot 'ur3' (did you mean 'joint4'?)"),
])
def test_config_errors_name_the_drive_and_line(tmp_path, drives, message):
    diagnostics = errors_of(write_config(tmp_path, one_bus(drives)))
    matching = [d for d in diagnostics if message in d.message]
    assert matching, [str(d) for d in diagnostics]
    assert matching[0].file.name == "bench.yaml" and matching[0].line


def test_yaml_syntax_error_has_a_line(tmp_path):
    path = tmp_path / "bad.yaml"
    path.write_text("robot: x.xacro\nbuses:\n  - name: [unclosed\n")
    (diag,) = errors_of(path)
    assert diag.line and "YAML syntax" in diag.message


def test_cycle_must_divide_plant_rate(tmp_path):
    diagnostics = errors_of(write_config(tmp_path, one_bus(ALL_SIX, 300)))
    assert any("does not divide plant_rate_hz 1000" in d.message for d in diagnostics)


def test_motor_side_defaults_come_from_the_robot(tmp_path):
    config = load_bus_config(write_config(tmp_path, one_bus(ALL_SIX, 250)))
    joint1 = config.drives[0]
    assert joint1.peak_torque == pytest.approx(100 / 120)       # effort / reduction
    assert joint1.max_velocity == pytest.approx(1.0 * 120)      # velocity limit x reduction
    assert joint1.position_limits == pytest.approx((-3.14 * 120, 3.14 * 120))
    assert joint1.following_error_limit == pytest.approx(0.1 * 120)


MIT = "protocol: mit, options: {p_max: 400, v_max: 130, kp_max: 50, kd_max: 1, t_max: 1, kp: 5, kd: 0.1}"


def test_mixed_protocols_share_a_bus_when_their_ids_do_not_collide(tmp_path):
    drives = ("- {node_id: 1, joint: joint1}\n- {node_id: 2, joint: joint2}\n"
              f"- {{node_id: 3, joint: joint3, {MIT[:-1]}, reply_id: 0x7F0}}}}\n"
              f"- {{node_id: 4, joint: joint4, {MIT[:-1]}, reply_id: 0x7F0}}}}\n"
              "- {node_id: 10, joint: joint5, protocol: odrive}\n"
              "- {node_id: 11, joint: joint6, protocol: odrive}\n")
    config = load_bus_config(write_config(tmp_path, one_bus(drives, 250)))
    bus = config.buses[0]
    # per cycle: 2 x (RPDO + 2 TPDO) + SYNC, 2 x (MIT command + answer), 2 x (ODrive
    # Set_Input_Pos, 2 RTRs, 2 answers); heartbeats: CiA 1 byte, ODrive 8 bytes, 10/s; the
    # ODrives' encoder estimates every 10 ms, as firmware 0.6 ships (issue 42)
    assert bus.load().frames_per_second == pytest.approx(250 * (6 + 1 + 4 + 10) + 4 * 10
                                                         + 2 * 100)


@pytest.mark.parametrize("drives, clash", [
    # MIT motors answer on the master's id 0 by default: CANopen's NMT id
    ("- {node_id: 1, joint: joint1}\n" + f"- {{node_id: 2, joint: joint2, {MIT}}}\n",
     "CAN id 0x000 is used by the master's NMT (cia402) and by node 2 (joint2) (mit)"),
    # ODrive node 4 uses ids 0x080-0x09F: SYNC and the CiA 402 drives' EMCY ids
    ("- {node_id: 1, joint: joint1}\n- {node_id: 4, joint: joint2, protocol: odrive}\n",
     "CAN id 0x080 is used by the master's SYNC (cia402) and by node 4 (joint2) "
     "(odrive)"),
    # an ODrive command id that is a MIT motor's id
    (f"- {{node_id: 33, joint: joint1, {MIT}}}\n- {{node_id: 1, joint: joint2, protocol: odrive}}\n",
     "CAN id 0x021 is used by node 33 (joint1) (mit) and by node 1 (joint2) (odrive)"),
])
def test_colliding_can_ids_of_mixed_protocols_are_rejected(tmp_path, drives, clash):
    rest = "".join(f"- {{node_id: {i + 90}, joint: joint{i}}}\n" for i in range(3, 7))
    diagnostics = errors_of(write_config(tmp_path, one_bus(drives + rest, 250)))
    assert any(clash in d.message for d in diagnostics), [d.message for d in diagnostics]


def two_odrive_buses(arm: int, bitrate: int, cycle_hz: int) -> str:
    """The ur3's six joints on ODrives: ``arm`` of them on bus 'arm', the rest on 'wrist'."""
    def bus(name: str, joints: range) -> str:
        drives = "".join(f"      - {{node_id: {j}, joint: joint{j}, protocol: odrive}}\n"
                         for j in joints)
        return (f"  - name: {name}\n    interface: virtual\n    channel: {name}\n"
                f"    bitrate: {bitrate}\n    cycle_hz: {cycle_hz}\n    drives:\n{drives}")
    return "buses:\n" + bus("arm", range(1, arm + 1)) + bus("wrist", range(arm + 1, 7))


def test_the_split_hint_of_a_bus_without_canopen_counts_no_sync(tmp_path):
    """A bus of ODrives carries no SYNC (CANSimple has none: the bus-wide frames are its
    protocols' own, Protocol.bus_wide_frames): the drives per bus the hint offers are those
    that fit under the warning's 80%, not fewer for a SYNC no drive needs (it offered 2)."""
    (diag,) = [d for d in errors_of(write_config(tmp_path, two_odrive_buses(4, 250000, 100)))
               if "infeasible" in d.message]
    assert "split the drives over buses of at most 3 drive(s) each" in diag.hint
    three = load_bus_config(write_config(tmp_path, two_odrive_buses(3, 250000, 100)))
    assert three.buses[0].load().worst_ratio <= 0.8


def test_benches_that_would_share_keys_or_a_bus_are_refused_naming_both(tmp_path):
    ur3 = load_bus_config(ROOT / "bus_config" / "ur3.yaml")
    with pytest.raises(HilError, match=r"robot 'ur3' is named by two configs"):
        check_together([ur3, load_bus_config(ROOT / "bus_config" / "ur3.yaml")])
    text = (ROOT / "bus_config" / "pigot.yaml").read_text()
    assert "channel: pigot/wrist" in text
    on_ur3s_bus = tmp_path / "pigot.yaml"
    on_ur3s_bus.write_text(text.replace("channel: pigot/wrist", "channel: ur3/wrist").replace(
        "robot: ../robots", f"robot: {ROOT / 'robots'}"))
    with pytest.raises(HilError) as refused:
        check_together([ur3, load_bus_config(on_ur3s_bus)])
    message = str(refused.value)
    assert "pigot.yaml:" in message and "ur3.yaml" in message
    assert "bus 'wrist' of robot 'pigot' is on channel 'ur3/wrist'" in message
    check_together([ur3, load_bus_config(ROOT / "bus_config" / "pigot.yaml")])


def test_a_misspelt_robot_name_is_answered_with_the_closest_known(tmp_path, monkeypatch,
                                                                 capsys):
    monkeypatch.chdir(tmp_path)
    assert main(["check", "pigott"]) == 1
    assert "no bus config for robot 'pigott' (did you mean 'pigot'?)" in capsys.readouterr().err


def test_a_robot_name_finds_its_bus_config_in_this_folder_first(tmp_path, monkeypatch, capsys):
    """Issue 64: `hil check myarm` beside `hil init`'s ./myarm.yaml said there was no bus
    config for it; the search order (docs/configuration.md): ./NAME.yaml, ./bus_config/,
    the shipped ones."""
    (tmp_path / "myarm.yaml").write_text(f"robot: {ROOT / UR3}\n" + one_bus(ALL_SIX, 250))
    (tmp_path / "bus_config").mkdir()
    (tmp_path / "bus_config" / "ur3.yaml").write_text("not: [a bus config")
    monkeypatch.chdir(tmp_path)
    assert main(["check", "myarm"]) == 0
    assert "bus config myarm.yaml" in capsys.readouterr().out
    assert main(["check", "ur3"]) == 1                 # ./bus_config/ before the shipped one
    assert "bus_config/ur3.yaml" in capsys.readouterr().err


def test_the_protocol_table_names_a_close_protocol_for_a_misspelt_one():
    from hil.protocols import protocol
    with pytest.raises(KeyError, match="no protocol 'cubemar' \\(did you mean 'cubemars'\\?\\)"):
        protocol("cubemar")


@pytest.mark.parametrize("protocol, options, carried", [
    ("damiao", "{model: DM4310}", "±12.5"), ("mit", "{kp: 1, kd: 0.1}", "±12.5"),
    ("cubemars", "{model: AK80-6}", "±12.56"), ("robstride", "{model: RS03}", "±12.57")])
def test_a_joint_past_what_its_drives_frames_carry_is_named_with_both_ranges(
        tmp_path, protocol, options, carried):
    """The UR3's joints turn their motors 100-120 times (its description's transmissions):
    an MIT-style actuator there, whose frames map a fixed range at its own shaft, saturates
    its commands and feedback within a tenth of the joint's range (`hil init ur3 --protocol
    damiao`, then the demo: OVERLOAD at joint4). `hil check` says so, naming both ranges."""
    drives = "".join(f"- {{node_id: {i}, joint: joint{i}, protocol: {protocol}, options: "
                     f"{options}}}\n" for i in range(1, 7))
    config = load_bus_config(write_config(tmp_path, one_bus(drives)))
    (warning,) = [w for w in config.warnings if "joint 'joint4' asks of its motor" in w.message]
    assert f"joint 'joint4' asks of its motor (reduction 100) ±314 rad (its range), the " \
           f"frames carry {carried};" in warning.message, warning.message
    assert "p_max/v_max" in warning.hint
