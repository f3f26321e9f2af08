"""`hil init`: a bus config any description can run at once, sized by a documented rule,
the description untouched; and the `transmissions:` a bus config carries."""

from __future__ import annotations

import hashlib
import math
import subprocess
import sys

import numpy as np
import pytest

from conftest import CORPUS
from hil.bus_config import load_bus_config
from hil.commissioning.initial import _drives_per_bus, worst_gravity_loads
from hil.commissioning.sizing import (
    DEFAULT_EFFORT_FLOOR, DEFAULT_EFFORT_MARGIN, DEFAULT_VELOCITY, MOTOR_CLASSES,
    ROTARY_REDUCTIONS, size_joint,
)
from hil.cli import main
from hil.description import (
    Joint, JointDynamics, JointLimits, JointType, PackagePath, Pose, load_description,
)
from hil.errors import HilError
from hil.protocols import protocol
from hil.plant.plant import INITIAL_MARGIN

REAL_WORLD = CORPUS / "real_world"
ARM = REAL_WORLD / "arm_folder" / "urdf" / "arm.urdf.xacro"
HAND = REAL_WORLD / "hand_without_limits.urdf"
ROOT_WITHOUT_INERTIAL = REAL_WORLD / "root_without_inertial.urdf"


def _joint(kind: JointType, effort: float, velocity: float) -> Joint:
    return Joint("j", kind, "a", "b", Pose(), (0.0, 0.0, 1.0),
                 JointLimits(-1.0, 1.0, effort, velocity), JointDynamics())


def test_sizing_takes_the_smallest_motor_class_and_then_the_smallest_reduction():
    sizing = size_joint(_joint(JointType.REVOLUTE, effort=40.0, velocity=2.0))
    for motor in MOTOR_CLASSES[:MOTOR_CLASSES.index(sizing.motor)]:     # none smaller fits
        assert not any(motor.peak_torque * n >= 40.0 and motor.top_speed / n >= 2.0
                       for n in ROTARY_REDUCTIONS)
    assert sizing.motor.peak_torque * sizing.reduction >= 40.0
    assert sizing.motor.top_speed / sizing.reduction >= 2.0
    smaller = [n for n in ROTARY_REDUCTIONS if n < sizing.reduction]
    assert all(sizing.motor.peak_torque * n < 40.0 for n in smaller)


def test_a_prismatic_joint_gets_a_ball_screw_lead():
    sizing = size_joint(_joint(JointType.PRISMATIC, effort=100.0, velocity=0.2))
    lead_mm = 2 * math.pi / sizing.reduction * 1000
    assert lead_mm in (40, 25, 20, 16, 10, 5, 4, 2, 1)
    assert sizing.motor.peak_torque * sizing.reduction >= 100.0


def test_a_joint_no_class_can_cover_says_so():
    sizing = size_joint(_joint(JointType.REVOLUTE, effort=1e6, velocity=100.0))
    assert sizing.motor is MOTOR_CLASSES[-1] and "no class covers both" in sizing.note


@pytest.mark.parametrize("protocol", ["cia402", "odrive", "mit"])
def test_init_writes_a_config_that_loads_with_a_drive_per_joint(protocol, tmp_path, capsys):
    before = hashlib.sha256(ARM.read_bytes()).hexdigest()
    output = tmp_path / "arm.yaml"
    assert main(["init", str(ARM), "--package-path", str(REAL_WORLD), "--protocol", protocol,
                 "-o", str(output)]) == 0
    assert f"wrote {output}: 2 {protocol} drive(s)" in capsys.readouterr().out
    config = load_bus_config(output, PackagePath((REAL_WORLD,)))
    assert [d.joints for d in config.drives] == [("shoulder",), ("elbow",)]
    assert {d.protocol for d in config.drives} == {protocol}
    robot = load_description(ARM, PackagePath((REAL_WORLD,)))
    for spec in config.robot.transmissions:          # as the sizing rule says
        sizing = size_joint(robot.joint(spec.joints[0].name))
        assert spec.actuators[0].reduction == pytest.approx(sizing.reduction)
        assert spec.actuators[0].rotor_inertia == pytest.approx(sizing.motor.rotor_inertia)
    assert hashlib.sha256(ARM.read_bytes()).hexdigest() == before    # untouched
    assert "left passive" not in output.read_text()


@pytest.mark.parametrize("protocol", ["cia402", "odrive", "mit", "damiao", "cubemars"])
def test_init_leaves_the_watchdog_to_the_protocols_default_and_says_which(protocol, tmp_path,
                                                                          capsys):
    """A drive out of its box keeps its maker's watchdog (an ODrive's is off until
    axis.config.enable_watchdog; MIT-family clients assume their motor's own): `hil init`
    writes none (it wrote 0.1 s for every protocol) and says what each protocol's drives
    run with, and whose default that is."""
    output = tmp_path / "arm.yaml"
    assert main(["init", str(ARM), "--package-path", str(REAL_WORLD), "--protocol", protocol,
                 "-o", str(output)]) == 0
    printed = capsys.readouterr().out
    assert not [line for line in output.read_text().splitlines()
                if line.strip().startswith("watchdog_timeout")]
    config = load_bus_config(output, PackagePath((REAL_WORLD,)))
    own = set()
    for drive in config.drives:
        product = drive.options.drive_defaults() if drive.options is not None else {}
        own.add("watchdog_timeout" in product)
        if "watchdog_timeout" in product:
            assert drive.watchdog_timeout == product["watchdog_timeout"]
    (said,) = [line for line in printed.splitlines() if line.strip().startswith("watchdog")]
    assert f"for the {protocol} drives on bus1" in said
    assert ("the protocol's own default" in said) == own.pop()


def _chain(tmp_path, joints: int = 12):
    """A chain of ``joints`` revolute joints, each carrying a 1 kg link."""
    links = "".join(f'<link name="l{i}"><inertial><mass value="1"/><inertia ixx="0.01" ixy="0" '
                    f'ixz="0" iyy="0.01" iyz="0" izz="0.01"/></inertial></link>'
                    for i in range(joints + 1))
    chain = "".join(f'<joint name="j{i}" type="revolute"><parent link="l{i}"/><child '
                    f'link="l{i + 1}"/><axis xyz="0 0 1"/><limit lower="-1" upper="1" '
                    f'effort="20" velocity="2"/></joint>' for i in range(joints))
    urdf = tmp_path / "chain.urdf"
    urdf.write_text(f'<robot name="chain">{links}{chain}</robot>')
    return urdf


def test_init_spreads_drives_over_buses_by_the_load_check(tmp_path):
    urdf = _chain(tmp_path)
    assert main(["init", str(urdf), "--rate", "1000", "-o", str(tmp_path / "c.yaml")]) == 0
    config = load_bus_config(tmp_path / "c.yaml")
    per_bus = _drives_per_bus(protocol("cia402"), 1000.0, False)
    assert len(config.buses) == math.ceil(12 / per_bus)
    assert all(bus.load().worst_ratio <= 0.8 for bus in config.buses)
    assert config.warnings == ()


@pytest.mark.parametrize("fd", [False, True], ids=["classical", "fd"])
def test_init_puts_damiao_drives_on_fd_buses_as_many_as_their_fd_load_allows(fd, tmp_path):
    output = tmp_path / "c.yaml"
    assert main(["init", str(_chain(tmp_path)), "--protocol", "damiao", "--rate", "1000",
                 "-o", str(output), *(["--fd"] if fd else [])]) == 0
    config = load_bus_config(output)
    per_bus = _drives_per_bus(protocol("damiao"), 1000.0, fd)
    assert len(config.buses) == math.ceil(12 / per_bus)
    assert all(bus.fd is fd for bus in config.buses)
    if fd:     # the data phase OpenArm's and moteus' benches run
        assert {bus.data_bitrate for bus in config.buses} == {5_000_000}
        assert per_bus > _drives_per_bus(protocol("damiao"), 1000.0, False)
    assert all(bus.load().worst_ratio <= 0.8 for bus in config.buses)


def test_init_sizes_a_moteus_bench_by_the_fd_load_of_its_data_phase(tmp_path):
    """moteus speaks CAN FD only: its buses are FD without --fd, and the drives each carries
    are counted with the 5 Mbit/s data phase it is written with."""
    output = tmp_path / "c.yaml"
    assert main(["init", str(_chain(tmp_path)), "--protocol", "moteus", "--rate", "1000",
                 "-o", str(output)]) == 0
    config = load_bus_config(output)
    assert all(bus.fd and bus.data_bitrate == 5_000_000 for bus in config.buses)
    assert len(config.buses) == math.ceil(12 / _drives_per_bus(protocol("moteus"), 1000.0, True))
    loads = [bus.load().worst_ratio for bus in config.buses]
    assert max(loads) <= 0.8
    # as many as fit: one drive more on the first bus would pass the limit
    assert loads[0] * (len(config.buses[0].drives) + 1) / len(config.buses[0].drives) > 0.8


def test_init_refuses_fd_for_drives_that_speak_classical_can_only(tmp_path, capsys):
    output = tmp_path / "c.yaml"
    assert main(["init", str(_chain(tmp_path)), "--fd", "-o", str(output)]) != 0
    err = capsys.readouterr().err
    assert "--fd: cia402 drives speak classical CAN only" in err
    assert "damiao, moteus" in err and "Traceback" not in err
    assert not output.exists()


def test_init_gives_joints_without_limits_the_default_class_and_says_so(tmp_path, capsys):
    output = tmp_path / "hand.yaml"
    assert main(["init", str(HAND), "-o", str(output)]) == 0
    printed = capsys.readouterr().out
    robot = load_description(HAND)
    worst = worst_gravity_loads(robot)
    config = load_bus_config(output)
    assert [d.joints[0] for d in config.drives] == [j.name for j in robot.movable_joints]
    for joint in robot.movable_joints:
        assert f"warning: joint '{joint.name}': the description gives effort 0, velocity 0" \
            in printed
        limits = config.robot.joint(joint.name).limits
        assert limits.velocity == DEFAULT_VELOCITY[JointType.REVOLUTE]
        assert limits.effort == pytest.approx(max(DEFAULT_EFFORT_FLOOR[JointType.REVOLUTE],
                                                  DEFAULT_EFFORT_MARGIN * worst[joint.name]),
                                              rel=1e-2)
        assert (limits.lower, limits.upper) == (0.0, 1.5)        # the description's range


def test_the_largest_gravity_load_is_the_carried_weight_at_its_distance_from_the_axis():
    # the hand's proximal finger joints carry two links of 0.03 kg, centred 0.02 m out on
    # each, the distal one 0.04 m out, bent by the start pose (its range starts at 0, so it
    # starts a tenth of the range inside); the axes (x) are horizontal
    bend = INITIAL_MARGIN * 1.5
    centre = (np.array([0.0, 0.02]) + [0.02 * math.sin(bend), 0.04 + 0.02 * math.cos(bend)]) / 2
    worst = worst_gravity_loads(load_description(HAND))
    assert worst["index_proximal_joint"] == pytest.approx(0.06 * 9.81 * np.linalg.norm(centre),
                                                          rel=1e-3)
    assert worst["index_distal_joint"] == pytest.approx(0.03 * 9.81 * 0.02, rel=1e-3)


@pytest.mark.parametrize("name", ["hand_without_limits.urdf", "effort_zero_passive.urdf",
                                  "arm_folder/urdf/arm.urdf.xacro", "transmission_on_mimic_"
                                  "joint.urdf", "shared_actuator.urdf"])
def test_check_and_init_agree_on_the_joints_a_drive_moves(name, tmp_path, capsys):
    """`hil check` of a description lists its driven joints and those `hil init` will give a
    drive; the config `hil init` writes drives exactly those."""
    package = ["--package-path", str(REAL_WORLD)]
    assert main(["check", str(REAL_WORLD / name), *package]) == 0
    summary = capsys.readouterr().out
    robot = load_description(REAL_WORLD / name, PackagePath((REAL_WORLD,)))
    promised = {j.name for j in robot.driven_joints + robot.undriven_joints}
    if robot.undriven_joints:
        assert f"{len(robot.undriven_joints)} passive (no transmission: `hil init`" in summary
    assert main(["init", str(REAL_WORLD / name), "-o", str(tmp_path / "c.yaml"), *package]) == 0
    config = load_bus_config(tmp_path / "c.yaml", PackagePath((REAL_WORLD,)))
    assert {j for d in config.drives for j in d.joints} == promised


def test_init_and_check_agree_that_a_root_link_without_inertial_is_fixed(tmp_path, capsys):
    """A root link without <inertial> (most hand-written URDFs) is fixed to the world, as
    URDF's tools take it (kdl_parser warns of a root link *with* one) and MuJoCo welds it:
    `hil check` says nothing of it, and `hil init` writes a fixed-base bench (it tried the
    robot on a floating base to see whether it stands, and MuJoCo refused the massless base:
    "mass and inertia of moving bodies must be larger than mjMINVAL")."""
    assert main(["check", str(ROOT_WITHOUT_INERTIAL)]) == 0
    assert "no warnings" in capsys.readouterr().out
    output = tmp_path / "arm.yaml"
    assert main(["init", str(ROOT_WITHOUT_INERTIAL), "-o", str(output)]) == 0
    config = load_bus_config(output)
    assert not config.floating_base and [d.joints for d in config.drives] == [("shoulder",)]


def test_a_floating_base_without_mass_is_an_error_on_its_line_that_says_what_to_do(tmp_path):
    config = tmp_path / "arm.yaml"
    config.write_text(f"robot: {ROOT_WITHOUT_INERTIAL}\nbase: floating\nscene:\n  - {{name: "
                      "floor, shape: plane}\ntransmissions:\n  shoulder: {reduction: 10}\n"
                      "buses:\n  - name: a\n    cycle_hz: 500\n    drives:\n      - "
                      "{node_id: 1, joint: shoulder}\n")
    with pytest.raises(HilError) as caught:
        load_bus_config(config)
    (error,) = caught.value.diagnostics
    assert error.line == 2 and "frees link 'base_link', which has no mass" in error.message
    assert "give link 'base_link' an <inertial>" in error.hint


def test_init_refuses_a_robot_without_a_joint_to_drive_and_says_why(tmp_path, capsys):
    urdf = tmp_path / "statue.urdf"
    urdf.write_text('<robot name="statue"><link name="a"/><link name="b"><inertial><mass '
                    'value="1"/><inertia ixx="0.01" ixy="0" ixz="0" iyy="0.01" iyz="0" '
                    'izz="0.01"/></inertial></link><joint name="j" type="fixed"><parent '
                    'link="a"/><child link="b"/></joint></robot>')
    output = tmp_path / "x.yaml"
    assert main(["init", str(urdf), "-o", str(output)]) == 1
    assert "has no joint hil can drive: no movable joint" in capsys.readouterr().err
    assert not output.exists()


def test_init_does_not_replace_a_file(tmp_path, capsys):
    output = tmp_path / "arm.yaml"
    output.write_text("mine")
    assert main(["init", str(ARM), "--package-path", str(REAL_WORLD), "-o", str(output)]) == 1
    assert "exists already" in capsys.readouterr().err and output.read_text() == "mine"


@pytest.mark.parametrize("section, entry, message", [
    ("transmissions", "nope: {reduction: 10}", "transmissions: joint 'nope' is not in the robot"),
    ("transmissions", "base_joint: {reduction: 10}",
     "transmissions: joint 'base_joint' is fixed and cannot move"),
    ("transmissions", "shoulder: {reduction: 0}", "'reduction' 0 is not within"),
    ("transmissions", "shoulder: {reduction: 1.0e+308}",         # overflowed the inertia
     "'reduction' 1e+308 is not within +-1e-05 to +-100000"),
    ("transmissions", "shoulder: {reduction: 10, rotor_inertia: -1.0}",
     "'rotor_inertia' must be 0 to 100"),
    ("transmissions", "shoulder: {reduction: 10, gear: 3}", "unknown key 'gear'"),
    ("joint_limits", "nope: {max_effort: 1}", "joint_limits: joint 'nope' is not in the robot"),
    ("joint_limits", "base_joint: {max_effort: 1}",
     "joint_limits: joint 'base_joint' cannot move"),
    ("joint_limits", "shoulder: {max_effort: 0}", "'max_effort' must be > 0"),
    ("joint_limits", "shoulder: {max_velocity: fast}", "'max_velocity' must be a number"),
    ("joint_limits", "shoulder: {max_accel: 3}", "unknown key 'max_accel'"),
])
def test_a_bad_config_transmission_or_joint_limit_is_an_error_on_its_line(section, entry, message,
                                                                          tmp_path):
    config = tmp_path / "arm.yaml"
    config.write_text(f"robot: {ARM}\n{section}:\n  {entry}\nbuses:\n  - name: a\n"
                      "    cycle_hz: 500\n    drives:\n      - {node_id: 1, joint: elbow}\n")
    with pytest.raises(HilError) as caught:
        load_bus_config(config, PackagePath((REAL_WORLD,)))
    (error,) = [d for d in caught.value.diagnostics if message in d.message]
    assert error.line == 3


def test_config_joint_limits_size_the_drive_over_the_descriptions(tmp_path):
    config = tmp_path / "hand.yaml"
    config.write_text(f"robot: {HAND}\njoint_limits:\n  index_proximal_joint: {{max_effort: 0.4, "
                      "max_velocity: 3}\ntransmissions:\n  index_proximal_joint: {reduction: "
                      "10}\nbuses:\n  - name: a\n    cycle_hz: 500\n    drives:\n      - "
                      "{node_id: 1, joint: index_proximal_joint}\n")
    (drive,) = load_bus_config(config).drives
    assert drive.peak_torque == pytest.approx(0.04) and drive.max_velocity == pytest.approx(30)


def test_a_config_transmission_on_a_joint_without_limits_names_joint_limits(tmp_path):
    config = tmp_path / "hand.yaml"
    config.write_text(f"robot: {HAND}\ntransmissions:\n  index_proximal_joint: {{reduction: "
                      "10}\nbuses:\n  - name: a\n    cycle_hz: 500\n    drives:\n      - "
                      "{node_id: 1, joint: index_proximal_joint}\n")
    with pytest.raises(HilError) as caught:
        load_bus_config(config)
    assert any("give it max_effort under 'joint_limits:'" in (d.hint or "")
               for d in caught.value.diagnostics), str(caught.value)


@pytest.mark.slow
def test_an_initialised_bench_runs_the_demo_and_records_the_meshes(tmp_path):
    config = tmp_path / "arm.yaml"
    assert main(["init", str(ARM), "--package-path", str(REAL_WORLD), "-o", str(config)]) == 0
    save = tmp_path / "arm.rrd"
    up = subprocess.run([sys.executable, "-m", "hil", "up", str(config), "--demo", "--lock-step",
                         "--no-viewer", "--package-path", str(REAL_WORLD), "--save", str(save)],
                        capture_output=True, text=True, timeout=240, cwd=tmp_path)
    assert up.returncode == 0, up.stdout[-3000:] + up.stderr[-3000:]
    assert "hil up: demo succeeded" in up.stdout
    assert set(mesh_entities(save)) == {"base", "upper", "forearm"}


def mesh_entities(rrd) -> dict[str, str]:
    """Link name -> media type of every mesh (Asset3D) the recording holds."""
    import rerun.chunk
    found = {}
    for chunk in rerun.chunk.RrdReader(rrd).store().stream():
        batch = chunk.to_record_batch()
        if "Asset3D:media_type" in batch.schema.names and "visual" in chunk.entity_path:
            link = chunk.entity_path.split("/visual_geometries/")[1].split("/")[0]
            found[link] = batch.column("Asset3D:media_type").to_pylist()[0][0]
    return found

