"""The one bounded reader every named file goes through (hil/input_files.py, issue 65): a
regular file checked before a byte is read, a size cap per kind, UTF-8 errors named with
their line, nesting counted before a recursive parser sees it, no XML document type (the
entity bomb), and a path the system cannot take named, each a HilError and never a hang or
a traceback."""

from __future__ import annotations

import json
import os
import re
from pathlib import Path

import pytest

from hil.bus_config import load_bus_config
from hil.description import PackagePath
from hil.errors import HilError
from hil.input_files import (MAX_NESTING, check_nesting, open_input_stream,
                             read_input_bytes, read_input_file)


def test_a_fifo_is_refused_without_waiting_for_a_writer(tmp_path):
    fifo = tmp_path / "eds.dcf"
    os.mkfifo(fifo)                   # opened plainly, a read would wait for a writer
    with pytest.raises(HilError, match="not a regular file"):
        read_input_bytes(fifo, "EDS", "give the vendor's EDS")


def test_a_file_over_its_kinds_cap_is_refused(tmp_path):
    log = tmp_path / "run.asc"
    log.write_bytes(b"x" * 2000)
    assert read_input_bytes(log, "CAN log", "give a log", limit=2000) == b"x" * 2000
    with pytest.raises(HilError, match="2001 bytes, over the 2000 hil reads"):
        log.write_bytes(b"x" * 2001)
        read_input_bytes(log, "CAN log", "give a log", limit=2000)


@pytest.mark.parametrize("size, limit, said", [
    (5000, 4096, "is 4.88 KiB, over the 4 KiB hil reads"),
    (4097, 4096, "is 4097 bytes, over the 4 KiB hil reads"),     # not "4 KiB, over the 4 KiB"
    (2001, 2000, "is 2001 bytes, over the 2000 hil reads"),
])
def test_a_size_over_the_cap_is_said_in_the_caps_unit(tmp_path, size, limit, said):
    """One reader for a config and a log alike (open_input_stream under read_input_bytes):
    the size and the cap are compared in one unit."""
    log = tmp_path / "run.blf"
    log.write_bytes(b"x" * size)
    with pytest.raises(HilError, match=re.escape(said)):
        open_input_stream(log, "CAN log", "give a log", limit)


def test_a_name_over_255_bytes_is_named(tmp_path):
    with pytest.raises(HilError, match="has a name of 300 bytes, over the 255"):
        read_input_file(tmp_path / ("x" * 300), "bus config", "give a file")


def test_a_byte_that_is_not_utf8_is_named_with_its_line(tmp_path):
    """YAML 1.2 (5.2), JSON (RFC 8259, 8.1) and XML without an encoding declaration
    (XML 1.0, 4.3.3) are UTF-8: a Latin-1 byte was replaced silently before."""
    config = tmp_path / "bus.yaml"
    config.write_bytes(b"robot: r.urdf\nbuses: []  # caf\xe9\n")
    with pytest.raises(HilError, match=r"bus.yaml:2: error: bus config is not UTF-8 text: "
                                       r"byte 0xE9"):
        read_input_file(config, "bus config", "give a file")


def test_a_json_200k_deep_is_refused_before_json_recurses(tmp_path):
    goal = tmp_path / "goal.json"
    goal.write_text("[" * 200_000 + "]" * 200_000)
    with pytest.raises(RecursionError):         # what a parser that recursed did
        json.loads(goal.read_text())
    with pytest.raises(HilError, match=f"nested more than {MAX_NESTING} deep"):
        read_input_file(goal, "trajectory", "give a file", syntax="json")


@pytest.mark.parametrize("syntax, text", [
    ("json", '{"a": ' * 101 + "1" + "}" * 101),
    ("yaml", "a: " + "[" * 101 + "]" * 101),
    ("yaml", "".join(f"{' ' * n}k{n}:\n" for n in range(101)) + " " * 101 + "v: 1\n"),
    ("xml", "<a>" * 101 + "</a>" * 101),
])
def test_nesting_past_the_bound_is_refused_in_each_syntax(tmp_path, syntax, text):
    with pytest.raises(HilError, match="nested more than 100 deep"):
        check_nesting(text, syntax, tmp_path / "f", "file")


@pytest.mark.parametrize("syntax, text", [
    # brackets inside strings and comments are no nesting (JSON5: both quotes, // and /* */)
    ("json", '{a: "' + "[" * 200 + '", b: \'{{{{\', // ' + "[" * 200 + "\n /* {{{{ */ c: [1]}"),
    ("yaml", "a: '" + "[" * 200 + "'\nb: [1, {c: 2}]  # " + "{" * 200 + "\n"),
    ("xml", "<a><!-- " + "<b>" * 200 + " --><c x='&lt;d&gt;'/></a>"),
])
def test_brackets_in_strings_and_comments_are_no_nesting(tmp_path, syntax, text):
    check_nesting(text, syntax, tmp_path / "f", "file")


def test_an_xml_entity_bomb_is_refused_before_it_expands(tmp_path):
    """An .epf is XML; a document type declaration may declare entities that expand to
    gigabytes (the "billion laughs"). No file hil reads declares one; defusedxml's
    forbid_dtd refuses them as this does."""
    bomb = tmp_path / "drive.epf"
    bomb.write_text('<?xml version="1.0"?>\n<!DOCTYPE lolz [\n <!ENTITY lol "lol">\n'
                    + "".join(f' <!ENTITY lol{n} "{f"&lol{n - 1};" * 10}">\n'
                              for n in range(1, 10)).replace("&lol0;", "&lol;")
                    + "]>\n<EPF>&lol9;</EPF>\n")
    with pytest.raises(HilError, match=r"drive.epf:2: error: EDS declares an XML document "
                                       r"type"):
        read_input_file(bomb, "EDS", "give the vendor's EDS", syntax="xml")


def test_an_xml_file_in_the_encoding_it_declares_is_read(tmp_path):
    """XML 1.0 section 4.3.3: a document not in UTF-8 declares its encoding (CAD exporters'
    URDFs in ISO-8859-1); one that declares none is UTF-8, and a byte that is not is named."""
    declared = tmp_path / "latin.urdf"
    declared.write_bytes(b'<?xml version="1.0" encoding="ISO-8859-1"?>\n'
                         b'<!-- 90\xb0 -->\n<robot name="r"/>\n')
    assert "90\u00b0" in read_input_file(declared, "description", "", syntax="xml")
    undeclared = tmp_path / "plain.urdf"
    undeclared.write_bytes(b'<robot name="r"><!-- 90\xb0 --></robot>\n')
    with pytest.raises(HilError, match="not UTF-8 text: byte 0xB0"):
        read_input_file(undeclared, "description", "", syntax="xml")


@pytest.mark.timeout(60)
@pytest.mark.parametrize("manifest", [
    # an entity named the package anything (ElementTree expanded it: 'evil' was found)
    '<?xml version="1.0"?>\n<!DOCTYPE p [<!ENTITY n "evil">]>\n<package><name>&n;</name>'
    '</package>\n',
    "<package><name>evil</name>" + "<a>" * 101 + "</a>" * 101 + "</package>",
    "fifo",                                         # a read would wait for a writer
])
def test_a_package_xml_hil_does_not_read_names_its_package_by_its_folder(tmp_path, manifest):
    """A package.xml (REP 149) is read as every named file is (hil/input_files.py): bounded,
    no document type, nested at most 100 deep; one that is not read leaves the package its
    folder's name, as a package.xml without a <name> does."""
    package = tmp_path / "arm"
    package.mkdir()
    if manifest == "fifo":
        os.mkfifo(package / "package.xml")
    else:
        (package / "package.xml").write_text(manifest)
    assert PackagePath((tmp_path,)).packages() == {"arm": package}


def _read_trajectory(path: Path):
    from hil.cli.send import goal_from_file
    return goal_from_file(path)


def _read_controllers(path: Path):
    from hil.bus_config.types import ControllersSource
    from hil.controllers.config import load_controllers
    return load_controllers(ControllersSource(path), ("j1",), 100.0)


def _read_bench_config(path: Path):
    from hil.bench.processes import config_at
    return config_at(path, 100.0, path.parent)


@pytest.mark.parametrize("read, name, what", [
    (load_bus_config, "bus.yaml", "bus config"),
    (_read_trajectory, "goal.yaml", "trajectory"),
    (_read_trajectory, "goal.json", "trajectory"),
    (_read_controllers, "ros2_controllers.yaml", "controllers file"),
    (_read_bench_config, "ur3.yaml", "bus config"),        # a RecursionError traceback
])
def test_a_file_nested_without_end_is_refused_at_its_line(tmp_path, read, name, what):
    """Each YAML and JSON file a user names is read with its nesting counted before the
    parser recurses (hil/input_files.py): the error names the line, where the parser's
    RecursionError named none (or was a traceback)."""
    path = tmp_path / name
    deep = "[" * 5000 + "]" * 5000
    path.write_text(f'{{"robot": "r.urdf",\n "points": {deep}}}\n' if name.endswith(".json")
                    else f"robot: r.urdf\npoints: {deep}\n")
    with pytest.raises(HilError, match=rf"{re.escape(name)}:2: error: {what} is nested more "
                                       rf"than 100 deep"):
        read(path)


@pytest.mark.timeout(60)
@pytest.mark.parametrize("endpoints, said", [
    ('{"endpoints":\n' + "[" * 5000 + "]" * 5000 + "}", r"nested more than 100 deep \(.*:2\)"),
    ("fifo", "is not a regular file"),                # a read waited for a writer
])
def test_an_odrive_endpoints_file_is_read_as_every_named_file(tmp_path, endpoints, said):
    """An ODrive's flat_endpoints.json goes through the bounded reader (hil/input_files.py):
    one 5000 deep was a RecursionError traceback from json.loads."""
    fixtures = Path(__file__).parent / "fixtures"
    if endpoints == "fifo":
        os.mkfifo(tmp_path / "flat_endpoints.json")
    else:
        (tmp_path / "flat_endpoints.json").write_text(endpoints)
    config = tmp_path / "odrive.yaml"
    config.write_text((fixtures / "odrive_one_axis.yaml").read_text()
                      .replace("robot: one_axis.urdf", f"robot: {fixtures / 'one_axis.urdf'}")
                      .replace("{node_id: 0, joint: yaw}",
                               "{node_id: 0, joint: yaw, options: "
                               "{endpoints: flat_endpoints.json}}"))
    with pytest.raises(HilError, match=f"odrive.yaml:.*endpoints file.* {said}"):
        load_bus_config(config)
