"""`hil init`: a bus config any description can run at once, sized by a documented rule,
the description untouched; and the `transmissions:` a bus config carries."""

from __future__ import annotations

import hashlib
import math
import subprocess
import sys

import pytest

from conftest import CORPUS
from hil.bus_config import load_bus_config
from hil.commissioning.initial import _drives_per_bus
from hil.commissioning.sizing import MOTOR_CLASSES, ROTARY_REDUCTIONS, size_joint
from hil.cli import main
from hil.description import (
    Joint, JointDynamics, JointLimits, JointType, PackagePath, Pose, load_description,
)
from hil.errors import HilError

REAL_WORLD = CORPUS / "real_world"
ARM = REAL_WORLD / "arm_folder" / "urdf" / "arm.urdf.xacro"


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


def test_init_spreads_drives_over_buses_by_the_load_check(tmp_path):
    links = "".join(f'<link name="l{i}"><inertial><mass value="1"/><inertia ixx="0.01" ixy="0" '
                    f'ixz="0" iyy="0.01" iyz="0" izz="0.01"/></inertial></link>'
                    for i in range(13))
    joints = "".join(f'<joint name="j{i}" type="revolute"><parent link="l{i}"/><child '
                     f'link="l{i + 1}"/><axis xyz="0 0 1"/><limit lower="-1" upper="1" '
                     f'effort="20" velocity="2"/></joint>' for i in range(12))
    urdf = tmp_path / "chain.urdf"
    urdf.write_text(f'<robot name="chain">{links}{joints}</robot>')
    assert main(["init", str(urdf), "--rate", "1000", "-o", str(tmp_path / "c.yaml")]) == 0
    config = load_bus_config(tmp_path / "c.yaml")
    per_bus = _drives_per_bus("cia402", 1000.0)
    assert len(config.buses) == math.ceil(12 / per_bus)
    assert all(bus.load().worst_ratio <= 0.8 for bus in config.buses)
    assert config.warnings == ()


def test_init_refuses_a_robot_without_a_joint_to_drive_and_says_why(tmp_path, capsys):
    output = tmp_path / "x.yaml"
    assert main(["init", str(REAL_WORLD / "effort_zero_passive.urdf"), "-o", str(output)]) == 1
    err = capsys.readouterr().err
    assert "has no joint hil can drive" in err
    assert "rotor_joint: the description gives no effort/velocity limit" in err
    assert not output.exists()


def test_init_does_not_replace_a_file(tmp_path, capsys):
    output = tmp_path / "arm.yaml"
    output.write_text("mine")
    assert main(["init", str(ARM), "--package-path", str(REAL_WORLD), "-o", str(output)]) == 1
    assert "exists already" in capsys.readouterr().err and output.read_text() == "mine"


@pytest.mark.parametrize("entry, message", [
    ("nope: {reduction: 10}", "transmissions: joint 'nope' is not in the robot"),
    ("base_joint: {reduction: 10}", "transmissions: joint 'base_joint' is fixed and cannot move"),
    ("shoulder: {reduction: 0}", "'reduction' must not be 0"),
    ("shoulder: {reduction: 10, rotor_inertia: -1.0}", "'rotor_inertia' must be >= 0"),
    ("shoulder: {reduction: 10, gear: 3}", "unknown key 'gear'"),
])
def test_a_bad_config_transmission_is_an_error_on_its_line(entry, message, tmp_path):
    config = tmp_path / "arm.yaml"
    config.write_text(f"robot: {ARM}\ntransmissions:\n  {entry}\nbuses:\n  - name: a\n"
                      "    cycle_hz: 500\n    drives:\n      - {node_id: 1, joint: elbow}\n")
    with pytest.raises(HilError) as caught:
        load_bus_config(config, PackagePath((REAL_WORLD,)))
    (error,) = [d for d in caught.value.diagnostics if message in d.message]
    assert error.line == 3


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

