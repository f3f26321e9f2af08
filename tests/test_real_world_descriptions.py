"""Descriptions as they are published load: each class of defect seen in public robots
(tests/corpus/real_world/, one minimal file each) is corrected with a warning that names
the element, its line and the change, or fails with file, line and what to do; --strict
turns every correction into an error; MuJoCo builds the corrected model."""

from __future__ import annotations

import pytest

from conftest import CORPUS
from hil.cli import main
from hil.description import PackagePath, load_description
from hil.errors import HilError, Severity
from hil.plant import Plant
from hil.plant.builder import build_spec, compile_model
from hil.transmissions import build_transmissions

REAL_WORLD = CORPUS / "real_world"


@pytest.fixture
def real_world_path() -> PackagePath:
    return PackagePath((REAL_WORLD,))


@pytest.mark.parametrize("name, line, message", [
    ("world_root.urdf", 4, "the root link is 'world': hil fixes its children to MuJoCo's world"),
    ("fixed_joint_zero_axis.urdf", 16, "2 fixed/floating joint(s) have <axis xyz=\"0 0 0\">, "
     "ignored as URDF ignores their axis: imu_joint, foot_joint"),
    ("inertia_unbalanced.urdf", 7, "link 'arm' inertia is not physical for MuJoCo; corrected: "
     "principal moments (0.001, 0.001, 0.01) -> (0.004, 0.004, 0.004) kg m^2"),
    ("inertia_not_positive.urdf", 7, "link 'arm' inertia is not physical for MuJoCo; corrected"),
    ("massless_moving_link.urdf", 7, "link 'virtual' moves but has no mass"),
    ("transmission_unknown_type.urdf", 14, "type 'pr2_mechanism_model/WristTransmission', which "
     "hil does not model: left out"),
    ("transmission_on_mimic_joint.urdf", 26, "drives mimic joint 'right_finger', which follows "
     "its leader: left out"),
    ("shared_actuator.urdf", 26, "names actuator 'hand_motor', which transmission "
     "'finger_1_trans' already drives: left out"),
    ("revolute_without_range.urdf", 10, "revolute joint 'wheel_joint' has no lower/upper limits"),
    ("effort_zero_passive.urdf", 10, "joint 'rotor_joint' limit effort is 0 or missing: taken "
     "as not given"),
    ("limit_without_effort.urdf", 11, "joint 'lid_joint' limit effort is 0 or missing: taken as "
     "not given"),
    ("hand_without_limits.urdf", 10, "joint 'index_proximal_joint' limit velocity is 0 or missing: taken as "
     "not given (`hil init` gives the joint hil's default class"),
    ("mimic_on_fixed_joint.urdf", 17, "fixed joint 'tip_joint' has a <mimic>, which does not "
     "move it: left out"),
    ("zero_size_visual.urdf", 8, "link 'tool' has a <visual> sphere of size 0: a placeholder, "
     "not drawn"),
    ("zero_size_visual.urdf", 8, "link 'tool' has a <visual> box of size 0 0 0"),
    ("numbers_with_commas.urdf", 10, "joint 'shoulder' origin rpy '1.5707963, 1.3089969, 0' "
     "separates its numbers with commas: read as '1.5707963 1.3089969 0'"),
    ("untidy_file.urdf", 1, "2 blank line(s) before the XML declaration"),
    ("untidy_file.urdf", 19, "1 NUL byte(s) in the file: removed"),
    ("undeclared_prefix.urdf", 15, "namespace prefix 'drake:' is used but never declared"),
    ("transmission_reduction_not_a_number.urdf", 17, "transmission 'shoulder_trans' has "
     "mechanical reduction 'reduction', which is not a number: left out"),
])
def test_a_published_defect_is_corrected_with_a_warning_and_the_plant_builds(
        name, line, message, real_world_path):
    description = load_description(REAL_WORLD / name, real_world_path)
    found = [w for w in description.warnings if message in w.message]
    assert found, [w.message for w in description.warnings]
    assert found[0].file.name == name and found[0].line == line and found[0].hint
    Plant(description)                                # MuJoCo accepts the corrected model
    with pytest.raises(HilError) as strict:
        load_description(REAL_WORLD / name, real_world_path, strict=True)
    assert any(message in d.message and d.severity is Severity.ERROR
               for d in strict.value.diagnostics)


def test_the_world_link_is_mujocos_world_body(real_world_path):
    plant = Plant(load_description(REAL_WORLD / "world_root.urdf", real_world_path))
    assert plant.model.body(1).name == "base" and plant.model.body_parentid[1] == 0


def test_a_corrected_inertia_keeps_the_mass_and_passes_mujocos_checks(real_world_path):
    description = load_description(REAL_WORLD / "inertia_not_positive.urdf", real_world_path)
    inertial = description.link("arm").inertial
    assert inertial.mass == 1.0
    moments = sorted((inertial.ixx, inertial.iyy, inertial.izz))
    assert moments[0] > 0 and moments[0] + moments[1] >= moments[2]


def test_a_ros1_transmission_with_its_type_as_attribute_drives_through_its_reduction(
        real_world_path):
    description = load_description(REAL_WORLD / "ros1_transmission_type_attribute.urdf",
                                   real_world_path)
    (transmission,) = build_transmissions(description)
    assert transmission.reduction == 80.0 and description.warnings == ()


def test_a_negative_simple_reduction_reverses_the_motor_as_in_ros2_control(package_path):
    description = load_description(CORPUS / "reduction_negative.urdf", package_path)
    (transmission,) = build_transmissions(description)
    assert transmission.joint_to_actuator_position([0.1])[0] == pytest.approx(-5.0)


@pytest.mark.parametrize("name, line, message", [
    ("transmission_unknown_joint.urdf", 16,
     "transmission 'shoulder_trans' names joint 'elbow', which does not exist: left out"),
    ("mimic_unknown_joint.urdf", 19,
     "joint 'finger_joint' mimics joint 'gripper_joint', which does not exist: the <mimic> is "
     "left out"),
])
def test_a_reference_to_a_missing_joint_is_left_out_with_a_warning(name, line, message,
                                                                   package_path):
    (warning,) = [w for w in load_description(CORPUS / name, package_path).warnings
                  if message in w.message]
    assert warning.line == line and warning.hint


@pytest.mark.parametrize("name, line, message, hint", [
    ("empty_robot.urdf", 3, "the robot has no <link>", "xacro macros alone"),
    ("effort_zero_driven.urdf", 10, "joint 'shoulder' is driven but its limit effort is 0 or missing",
     "the drive is sized from it"),
])
def test_what_cannot_be_corrected_fails_with_file_line_and_what_to_do(name, line, message,
                                                                       hint, real_world_path):
    with pytest.raises(HilError) as caught:
        load_description(REAL_WORLD / name, real_world_path)
    (error,) = [d for d in caught.value.diagnostics if d.severity is Severity.ERROR]
    assert message in error.message and hint in error.hint
    assert error.file.name == name and error.line == line


def test_meshes_resolve_by_package_name_folder_name_and_relative_to_their_include(
        real_world_path):
    description = load_description(REAL_WORLD / "arm_folder" / "urdf" / "arm.urdf.xacro",
                                   real_world_path)
    meshes = {link.name: link.visuals[0].geometry.mesh for link in description.links
              if link.visuals}
    folder = REAL_WORLD / "arm_folder"
    assert meshes == {"base": folder / "meshes" / "base.stl",
                      "upper": folder / "meshes" / "upper.stl",
                      "forearm": folder / "urdf" / "parts" / "meshes" / "fore.stl"}


def test_the_plant_draws_the_meshes_mujoco_reads_and_says_which_it_cannot(real_world_path):
    plant = Plant(load_description(REAL_WORLD / "arm_folder" / "urdf" / "arm.urdf.xacro",
                                   real_world_path))
    assert sorted(plant.model.mesh(i).name for i in range(plant.model.nmesh)) == [
        "base_visual_0", "upper_visual_0"]                  # binary STL
    (warning,) = plant.warnings                              # forearm's is ASCII STL
    assert "link 'forearm' mesh" in warning.message and "ASCII" in warning.message
    assert "the recording draws the mesh" in warning.message and "binary STL" in warning.hint


def test_hil_check_names_the_folder_each_package_resolved_to(capsys):
    assert main(["check", str(REAL_WORLD / "arm_folder" / "urdf" / "arm.urdf.xacro"),
                 "--package-path", str(REAL_WORLD)]) == 0
    out = capsys.readouterr().out
    assert f"package 'arm_description': {REAL_WORLD / 'arm_folder'}" in out
    assert f"package 'arm_folder': {REAL_WORLD / 'arm_folder'}" in out
    assert "2 passive (no transmission: `hil init`" in out


def test_a_missing_package_is_named_as_the_cause_of_a_missing_mesh(tmp_path):
    urdf = tmp_path / "robot.urdf"
    urdf.write_text('<robot name="r"><link name="base"><visual><geometry><mesh '
                    'filename="package://no_such_pkg/meshes/base.stl"/></geometry></visual>'
                    '</link></robot>')
    (warning,) = load_description(urdf, PackagePath((tmp_path,))).warnings
    assert "package 'no_such_pkg' is not on the package path" in warning.message
    assert "--package-path" in warning.hint


def test_a_mujoco_rejection_names_the_link_with_its_file_and_line(real_world_path):
    description = load_description(REAL_WORLD / "world_root.urdf", real_world_path)
    spec, _ = build_spec(description, build_transmissions(description))
    spec.body("arm").mass = -1.0                  # what no correction leaves: MuJoCo says no
    with pytest.raises(HilError) as caught:
        compile_model(spec, description)
    (error,) = caught.value.diagnostics
    lines = (REAL_WORLD / "world_root.urdf").read_text().splitlines()
    assert error.file.name == "world_root.urdf"
    assert '<link name="arm">' in lines[error.line - 1]
    assert "MuJoCo rejects the model" in error.message and "link 'arm'" in error.hint
