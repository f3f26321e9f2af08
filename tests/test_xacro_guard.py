"""A description runs no code and reads nothing outside what the user allowed (issue 43:
`hil check` of a .xacro ran a shell command through a comprehension's code object; `$(env)`
and includes of any file, /dev/zero among them, were honoured)."""

from __future__ import annotations

import math
import os
import shutil
from pathlib import Path

import pytest

from hil.description import PackagePath, load_description
from hil.description.xacro_expressions import Refused, evaluate
from hil.description.xacro_guard import ALLOWED_ENV_VARIABLE
from hil.errors import HilError

HEADER = '<?xml version="1.0"?>\n<robot name="probe" xmlns:xacro="http://www.ros.org/wiki/xacro">\n'
LINK = ('<link name="{name}"><inertial><mass value="1"/><inertia ixx="1" ixy="0" ixz="0" '
        'iyy="1" iyz="0" izz="1"/></inertial></link>\n')


def _load(tmp_path, body: str, name: str = "probe.xacro"):
    path = tmp_path / name
    path.write_text(HEADER + body + "</robot>\n")
    return load_description(path, PackagePath(()))


def test_the_comprehension_escape_runs_nothing(tmp_path):
    marker = tmp_path / "PWNED"
    payload = ("[c for c in ().__class__.__base__.__subclasses__() if c.__name__ == "
               "'catch_warnings'][0]()._module.__builtins__['__import__']('os')"
               f".system('touch {marker}')")
    with pytest.raises(HilError, match="ListComp is not allowed"):
        _load(tmp_path, f'<xacro:property name="x" value="${{{payload}}}"/>\n'
                        + LINK.format(name="${x}"))
    assert not marker.exists()


@pytest.mark.parametrize("expression", [
    "().__class__", "(1).real.__class__", "'{0.__class__}'.format(1)", "f'{1}'",
    "(lambda: 1)()", "[x for x in [1]]", "python.type(1)", "python.vars()",
    "9 ** 9 ** 9", "'a' * 10 ** 9", "1 << 10 ** 9",
    # a string's methods that reach further or grow with an argument
    "'{0}'.format_map({})", "'ab'.replace('', 'x' * 900000)", "','.join(['x'] * 10)",
    "'a'.center(10 ** 9)", "'a'.encode()", "'a'.find.__self__", "'a'.__len__()",
])
def test_an_expression_beyond_arithmetic_is_refused(expression):
    import xacro
    with pytest.raises(Refused):
        evaluate(expression, xacro._global_symbols)


@pytest.mark.parametrize("expression, expected", [
    ("radians(90)", math.pi / 2), ("math.sqrt(16) + pi", 4 + math.pi),
    ("1 if 2 > 1 else 0", 1), ("[1, 2, 3][-1] * 2", 6), ("max(1, 5) - min(2, 3)", 3),
    ("len('abc') + python.abs(-1) + round(2.6)", 7), ("not (1 == 2) and 3 in [3]", True),
    ("{'a': 1}['a']", 1), ("str(1) + 'x'", "1x"), ("2 ** 10", 1024),
    # a string's reading methods (Enactic's openarm_description: prefix.find('right_'))
    ("'openarm_right_'.find('right_') != -1", True), ("'left_arm'.startswith('left')", True),
    ("'A_b'.lower().split('_')", ["a", "b"]), ("'x.dae'.endswith('.dae')", True),
])
def test_the_arithmetic_public_descriptions_use_still_evaluates(expression, expected):
    import xacro
    assert evaluate(expression, xacro._global_symbols) == pytest.approx(expected) \
        if isinstance(expected, float) else evaluate(expression, xacro._global_symbols) \
        == expected


@pytest.mark.parametrize("include", ["/dev/zero", "/etc/hostname", "../outside.xacro"])
def test_an_include_outside_the_allowed_folders_is_refused(tmp_path, include):
    (tmp_path / "outside.xacro").write_text(HEADER + "</robot>\n")
    inner = tmp_path / "robot"
    inner.mkdir()
    with pytest.raises(HilError, match="outside the description's folder"):
        _load(inner, f'<xacro:include filename="{include}"/>\n' + LINK.format(name="base"))


def test_an_include_inside_the_descriptions_folder_is_read(tmp_path):
    (tmp_path / "part.xacro").write_text(
        HEADER.replace("probe", "part") + '<xacro:property name="w" value="2"/>\n</robot>\n')
    robot = _load(tmp_path, '<xacro:include filename="part.xacro"/>\n'
                            + LINK.format(name="base_${w}"))
    assert robot.root_link == "base_2"


def test_load_yaml_outside_the_allowed_folders_is_refused(tmp_path):
    with pytest.raises(HilError, match="outside the description's folder"):
        _load(tmp_path, '<xacro:property name="y" value="${xacro.load_yaml(\'/etc/passwd\')}"/>\n'
                        + LINK.format(name="${y}"))


def test_env_reads_only_the_variables_the_user_names(tmp_path, monkeypatch):
    monkeypatch.setenv("HIL_PROBE_SECRET", "s3cret")
    monkeypatch.delenv(ALLOWED_ENV_VARIABLE, raising=False)
    with pytest.raises(HilError, match="HIL_PROBE_SECRET is not set"):
        _load(tmp_path, LINK.format(name="$(env HIL_PROBE_SECRET)"))
    robot = _load(tmp_path, LINK.format(name="x$(optenv HIL_PROBE_SECRET none)"), "opt.xacro")
    assert robot.root_link == "xnone"                  # not named: as if unset
    monkeypatch.setenv(ALLOWED_ENV_VARIABLE, "HIL_PROBE_SECRET")
    assert _load(tmp_path, LINK.format(name="$(env HIL_PROBE_SECRET)"),
                 "named.xacro").root_link == "s3cret"


def test_eval_substitution_is_arithmetic_only(tmp_path):
    robot = _load(tmp_path, '<xacro:arg name="n" default="2"/>\n'
                            + LINK.format(name="l$(eval 1 + n * 3)"))
    assert robot.root_link == "l7"
    with pytest.raises(HilError, match="not allowed"):
        _load(tmp_path, '<xacro:arg name="n" default="2"/>\n'
                        + LINK.format(name="l$(eval n.__class__)"), "evil.xacro")


#: a mesh of the test corpus
STL = Path(__file__).parent / "corpus" / "real_world" / "arm_folder" / "meshes" / "base.stl"


def _robot_with_mesh(filename: str) -> str:
    inertial = ('<inertial><mass value="1"/><inertia ixx="0.01" iyy="0.01" izz="0.01" ixy="0" '
                'ixz="0" iyz="0"/></inertial>')
    return (f'<robot name="m"><link name="a"><visual><geometry><mesh filename="{filename}"/>'
            f'</geometry></visual>{inertial}</link><link name="b">{inertial}</link>'
            '<joint name="j" type="revolute"><parent link="a"/><child link="b"/>'
            '<axis xyz="0 0 1"/><limit lower="-1" upper="1" effort="1" velocity="1"/></joint>'
            '</robot>')


def test_a_mesh_is_read_inside_the_descriptions_package_and_refused_outside(tmp_path):
    """Meshes, like includes, only inside the description's folder (its package's, so that
    ../meshes beside urdf/ is read) and the package path (issue 43)."""
    package = tmp_path / "my_robot"
    (package / "urdf").mkdir(parents=True)
    (package / "meshes").mkdir()
    (package / "package.xml").write_text("<package><name>my_robot</name></package>")
    shutil.copy(STL, package / "meshes" / "a.stl")
    outside = tmp_path / "elsewhere.stl"
    shutil.copy(STL, outside)
    inside = package / "urdf" / "inside.urdf"
    inside.write_text(_robot_with_mesh("../meshes/a.stl"))
    found = load_description(inside, PackagePath(())).link("a").visuals[0].geometry.mesh
    assert found.resolve() == package / "meshes" / "a.stl"
    refused = package / "urdf" / "refused.urdf"
    refused.write_text(_robot_with_mesh(f"file://{outside}"))
    robot = load_description(refused, PackagePath(()))
    assert robot.link("a").visuals[0].geometry.mesh is None
    assert any("hil reads no file there" in warning.message for warning in robot.warnings)


def test_a_glob_include_reads_each_file_it_matches(tmp_path):
    """xacro includes every file a glob matches, sorted (xacro's get_include_files: "Globbing
    behaviour", glob.glob of the name); each is checked as a file, the glob's folder is no
    file to refuse (it was: "'.../parts' is not a regular file")."""
    package = tmp_path / "my_robot"
    (package / "parts").mkdir(parents=True)
    (package / "package.xml").write_text("<package><name>my_robot</name></package>")
    for part, width in (("a", 2), ("b", 3)):
        (package / "parts" / f"{part}.xacro").write_text(
            HEADER.replace("probe", part)
            + f'<xacro:property name="w_{part}" value="{width}"/>\n</robot>\n')
    robot = _load(package, '<xacro:include filename="parts/*.xacro"/>\n'
                           + LINK.format(name="base_${w_a}_${w_b}"))
    assert robot.root_link == "base_2_3"


def test_a_glob_include_matching_a_file_hil_does_not_read_is_refused(tmp_path):
    """Each file a glob matches is checked as a named include is: a FIFO among them waited
    for a writer without end."""
    (tmp_path / "parts").mkdir()
    (tmp_path / "parts" / "a.xacro").write_text(HEADER.replace("probe", "a") + "</robot>\n")
    os.mkfifo(tmp_path / "parts" / "b.xacro")
    with pytest.raises(HilError, match=r"b\.xacro' is not a regular file"):
        _load(tmp_path, '<xacro:include filename="parts/*.xacro"/>\n' + LINK.format(name="x"))


def test_an_included_file_is_read_as_every_named_file(tmp_path):
    """An include and xacro.load_yaml are read through hil's reader (hil/input_files.py), as
    the description itself is: an include's document type declared an entity that xacro's
    open() and minidom expanded (the description's link was named 'base_evil'); a YAML
    nested 5000 deep was PyYAML's RecursionError, taken for "an expression nested too
    deeply", naming neither the YAML file nor its line."""
    (tmp_path / "part.xacro").write_text(
        '<?xml version="1.0"?>\n<!DOCTYPE r [<!ENTITY n "evil">]>\n'
        + HEADER.split("\n", 1)[1].replace("probe", "part")
        + '<xacro:property name="w" value="&n;"/>\n</robot>\n')
    with pytest.raises(HilError, match=r"part\.xacro: error: xacro: included file declares an "
                                       r"XML document type .*part\.xacro:2\)"):
        _load(tmp_path, '<xacro:include filename="part.xacro"/>\n'
                        + LINK.format(name="base_${w}"))
    (tmp_path / "deep.yaml").write_text("a: " + "[" * 5000 + "]" * 5000 + "\n")
    with pytest.raises(HilError, match=r"YAML file is nested more than 100 deep "
                                       r"\(.*deep\.yaml:1\)"):
        _load(tmp_path, '<xacro:property name="y" value="${xacro.load_yaml(\'deep.yaml\')}"/>\n'
                        + LINK.format(name="l${len(y)}"), "yaml.xacro")


def test_an_include_in_the_encoding_it_declares_is_read(tmp_path):
    """XML 1.0, 4.3.3: a CAD exporter's file in ISO-8859-1 says so; read as it says."""
    (tmp_path / "part.xacro").write_bytes(
        b'<?xml version="1.0" encoding="ISO-8859-1"?>\n'
        + HEADER.split("\n", 1)[1].replace("probe", "part").encode()
        + b'<!-- 90\xb0 --><xacro:property name="w" value="2"/>\n</robot>\n')
    robot = _load(tmp_path, '<xacro:include filename="part.xacro"/>\n'
                            + LINK.format(name="base_${w}"))
    assert robot.root_link == "base_2"


def test_a_missing_include_is_named_by_xacro_or_skipped_where_optional(tmp_path):
    """xacro's own handling of a file that is not there stays (its process_include: an
    ``optional="true"`` include of it is skipped, any other an error naming it)."""
    robot = _load(tmp_path, '<xacro:include filename="gone.xacro" optional="true"/>\n'
                            + LINK.format(name="base"))
    assert robot.root_link == "base"
    with pytest.raises(HilError, match=r"strict\.xacro:3: error: included file "
                                       r"'.*gone\.xacro' does not exist"):
        _load(tmp_path, '<xacro:include filename="gone.xacro"/>\n' + LINK.format(name="base"),
              "strict.xacro")
