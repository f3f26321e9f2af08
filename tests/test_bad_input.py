"""Every defect of the bad-input corpus gets a clear message: file, line, what to do.

The corpus (tests/corpus/) is built from the seeds' own defects.
"""

from __future__ import annotations

import subprocess
import sys

from pathlib import Path

import pytest

from hil.cli import main
from hil.description import PackagePath, load_description
from hil.errors import HilError, Severity
from conftest import CORPUS


def diagnostics_of(path, package_path, strict=False):
    with pytest.raises(HilError) as caught:
        load_description(path, package_path, strict=strict)
    return caught.value.diagnostics


def test_every_comment_inside_a_start_tag_is_named_with_file_line_and_tag(package_path):
    diagnostics = diagnostics_of(CORPUS / "pigot_arm_model_as_printed.xacro", package_path)
    assert len(diagnostics) == 11          # the seed has eleven: one run finds them all
    assert [d.line for d in diagnostics] == sorted(d.line for d in diagnostics)
    diag = diagnostics[0]
    assert diag.file.name == "pigot_arm_model_as_printed.xacro"
    assert diag.line == 12  # xyz="0 -0.3 0.05"   <!--原点坐标x,y,z-->
    assert "XML comment inside the start tag of <origin>" in diag.message
    assert "move the comment after the '>'" in diag.hint


def test_seed_ur3_duplicate_transmission_and_actuator_names(package_path):
    diagnostics = diagnostics_of(CORPUS / "ur3_as_published.xacro", package_path)
    errors = [d for d in diagnostics if d.severity is Severity.ERROR]
    assert len(errors) == 2
    trans, motor = errors
    assert "transmission name 'trans1' is used by 6 transmissions" in trans.message
    assert "joint1; joint2; joint3; joint4; joint5; joint6" in trans.message
    assert trans.line == 9 and "${joint_name}" in trans.hint
    assert "actuator name 'motor1' is used by 6 transmissions" in motor.message
    assert motor.line == 14


def test_seed_ur3_warnings_travel_with_its_errors(package_path):
    diagnostics = diagnostics_of(CORPUS / "ur3_as_published.xacro", package_path)
    text = "\n".join(d.message for d in diagnostics if d.severity is Severity.WARNING)
    assert "link 'link3' colour rgba=\"1 10 13 1\"" in text
    assert "link 'base_link' visual origin is 25.0 m" in text
    assert "mesh 'package://ur3/meshes/base_link.STL' not found: package 'ur3'" in text


@pytest.mark.parametrize("name, message, hint", [
    ("rgba_above_one.urdf", "colour rgba=\"1 10 13 1\" has components outside 0..1",
     "divide 0-255 values by 255"),
    ("visual_far_away.urdf", "visual origin is 25.0 m from the link frame",
     "unit or export error"),
    ("mesh_missing.urdf", "mesh 'package://ur3/meshes/base_link.STL' not found: package 'ur3' "
     "is not on the package path", "--package-path"),
])
def test_cosmetic_defects_warn_with_line_and_still_load(name, message, hint, package_path):
    description = load_description(CORPUS / name, package_path)
    (diag,) = description.warnings
    assert message in diag.message and hint in diag.hint
    assert diag.file.name == name and diag.line == 7


def test_strict_turns_a_missing_mesh_into_an_error(package_path):
    (diag,) = diagnostics_of(CORPUS / "mesh_missing.urdf", package_path, strict=True)
    assert diag.severity is Severity.ERROR and "not found" in diag.message


def test_unknown_package_lists_the_search_path(package_path):
    (diag,) = diagnostics_of(CORPUS / "find_unknown_package.xacro", package_path)
    assert "$(find pigot_stl_model): no package named 'pigot_stl_model'" in diag.message
    assert str(CORPUS) in diag.message  # the search path is listed
    assert diag.line == 6
    assert "--package-path" in diag.hint and "HIL_PACKAGE_PATH" in diag.hint


def test_undefined_parent_link_names_the_file_missing_from_includes(package_path):
    root = CORPUS / "missing_include_description" / "urdf"
    (diag,) = diagnostics_of(root / "robot.xacro", package_path)
    assert "parent link 'body_link' is not defined" in diag.message
    assert diag.file.name == "arm.xacro" and diag.line == 3
    assert "body.xacro, which is not included" in diag.hint
    assert "$(find missing_include_description)/urdf/body.xacro" in diag.hint


_XACRO = '<?xml version="1.0"?>\n<robot name="r" xmlns:xacro="http://www.ros.org/wiki/xacro">\n'


@pytest.mark.parametrize("body, line, message", [
    ('<link name="a"/>\n<link name="b" value="${mass_of_b * 2}"/>\n', 4,
     "name 'mass_of_b' is not defined"),
    ('<xacro:macro name="m" params="x y"><link name="${x}"/></xacro:macro>\n<xacro:m x="q"/>\n',
     3, "Undefined parameters [y]"),
    ('<link name="a"/>\n<xacro:no_such_macro x="q"/>\n', 4, "unknown macro name"),
    ('<link name="a"/>\n<link name="$(arg not_given)"/>\n', 4,
     "Undefined substitution argument not_given"),
])
def test_a_xacro_error_names_the_line_that_causes_it(body, line, message, tmp_path):
    path = tmp_path / "robot.xacro"
    path.write_text(_XACRO + body + "</robot>\n")
    (diag,) = diagnostics_of(path, PackagePath(()))
    assert message in diag.message and (diag.file, diag.line) == (path, line)


def test_a_file_without_links_names_its_robot_element(tmp_path):
    path = tmp_path / "macros.xacro"
    path.write_text(_XACRO + '<xacro:macro name="arm" params="prefix">\n'
                    '<link name="${prefix}base"/></xacro:macro>\n</robot>\n')
    (diag,) = diagnostics_of(path, PackagePath(()))
    assert "has no <link>" in diag.message and diag.line == 2


def test_a_package_root_given_relative_to_the_working_folder_resolves_find(monkeypatch):
    # the package path's stand-in ament prefix once linked a relative root as given, so
    # every $(find pkg) include under it "did not exist"
    monkeypatch.chdir(CORPUS.parent)
    root = Path(CORPUS.name)
    (diag,) = diagnostics_of(root / "missing_include_description" / "urdf" / "robot.xacro",
                             PackagePath((root,)))
    assert "parent link 'body_link' is not defined" in diag.message     # the include was read


def test_an_include_fragment_given_alone_is_called_one_not_sent_to_another_robots_file(
        package_path):
    # body_link is defined on the package path, by another robot's package: no answer here
    (diag,) = diagnostics_of(CORPUS / "real_world" / "gripper_fragment.urdf", package_path)
    assert "parent link 'body_link' is not defined" in diag.message and diag.line == 9
    assert "looks like a fragment that a robot's main file includes" in diag.hint
    assert "body.xacro" not in diag.hint


@pytest.mark.parametrize("name, line, message", [
    ("reduction_zero.urdf", 16, "actuator 'shoulder_motor' has mechanical reduction 0, not within"),
    ("limits_inverted.urdf", 10, "joint 'shoulder' limits lower=1.5 > upper=-1.5"),
])
def test_semantic_errors_name_the_element_and_line(name, line, message, package_path):
    errors = [d for d in diagnostics_of(CORPUS / name, package_path)
              if d.severity is Severity.ERROR]
    assert len(errors) == 1
    assert message in errors[0].message
    assert errors[0].file.name == name and errors[0].line == line
    assert errors[0].hint


def test_cli_reports_errors_without_traceback_and_exits_1(capsys):
    assert main(["check", str(CORPUS / "ur3_as_published.xacro"),
                 "--package-path", str(CORPUS)]) == 1
    err = capsys.readouterr().err
    assert "ur3_as_published.xacro:9: error: transmission name 'trans1'" in err
    assert "what to do:" in err


def test_cli_process_prints_no_traceback_for_malformed_xml():
    result = subprocess.run(
        [sys.executable, "-m", "hil", "check", str(CORPUS / "pigot_arm_model_as_printed.xacro")],
        capture_output=True, text=True, timeout=120)
    assert result.returncode == 1
    assert "Traceback" not in result.stderr
    assert "pigot_arm_model_as_printed.xacro:12: error: XML comment inside" in result.stderr


def test_missing_file_is_a_clear_error(tmp_path, capsys):
    assert main(["check", str(tmp_path / "nope.urdf")]) == 1
    assert "does not exist" in capsys.readouterr().err
