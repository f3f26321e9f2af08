"""hil's error family (issue 66 item 5): what the user wrote or gave (a file and its line, or
a command-line value, and what to write) apart from what happened on a running bench (a
bus, a node, a device), each a type a user's test can catch, as python-can's ``CanError`` ->
``CanInitializationError`` / ``CanOperationError`` / ``CanTimeoutError`` and canopen's
``SdoError`` -> ``SdoAbortedError(code)``; all of them the ``HilError`` the CLI prints
without a traceback."""

from __future__ import annotations

import pytest

from conftest import ROOT
from hil.bus_config import config_path, load_bus_config
from hil.cli import main
from hil.description import load_description
from hil.errors import (
    BootTimeout, BringUpError, BusError, ConfigError, DriveError, EnableError, HilError,
    ProcessError, RuntimeFault, UsageError,
)

CONFIG_KINDS = (ConfigError, UsageError)
RUNTIME_KINDS = (RuntimeFault, BusError, DriveError, ProcessError, BringUpError, BootTimeout,
                 EnableError)


def ur3_config(tmp_path, old: str, new: str):
    """The shipped ur3 bus config with ``old`` written ``new``, and the line it is on."""
    text = (ROOT / "bus_config" / "ur3.yaml").read_text().replace("../robots/",
                                                                   f"{ROOT}/robots/")
    assert text.count(old) == 1
    path = tmp_path / "ur3.yaml"
    path.write_text(text.replace(old, new))
    return path, text[:text.index(old)].count("\n") + 1


def test_a_bad_bus_config_raises_a_config_error_naming_its_file_and_line(tmp_path):
    path, line = ur3_config(tmp_path, "{node_id: 3, joint: joint3",
                            "{node_id: 300, joint: joint3")
    with pytest.raises(ConfigError) as caught:
        load_bus_config(path)
    assert (caught.value.path, caught.value.line) == (path, line)
    assert "node id 300" in str(caught.value) and f"{path}:{line}" in str(caught.value)


def test_malformed_yaml_raises_a_config_error_at_its_line(tmp_path):
    path, line = ur3_config(tmp_path, "    cycle_hz: 500\n    drives:\n      - {node_id: 1",
                            "    cycle_hz: 500\n    drives:\n      - {node_id: [1")
    with pytest.raises(ConfigError) as caught:
        load_bus_config(path)
    assert caught.value.path == path and caught.value.line is not None


def test_a_malformed_robot_description_raises_a_config_error_at_its_line(tmp_path):
    urdf = tmp_path / "broken.urdf"
    urdf.write_text('<robot name="broken">\n  <link name="base"/>\n  <link name="arm">\n'
                    "</robot>\n")
    with pytest.raises(ConfigError) as caught:
        load_description(urdf)
    assert caught.value.path == urdf and caught.value.line == 4


def test_a_command_line_value_is_a_usage_error_the_cli_reports_without_a_traceback(capsys):
    with pytest.raises(UsageError) as caught:
        config_path("nosuch")
    assert caught.value.path is None
    assert main(["describe", "nosuch"]) == 1
    said = capsys.readouterr().err
    assert "no bus config for robot 'nosuch'" in said and "Traceback" not in said


@pytest.mark.parametrize("kind", CONFIG_KINDS + RUNTIME_KINDS)
def test_every_kind_is_a_hil_error_of_one_family(kind):
    assert issubclass(kind, HilError)
    assert issubclass(kind, ConfigError) != issubclass(kind, RuntimeFault)


def test_a_runtime_fault_says_where_it_happened():
    fault = DriveError.single("no answer to the SDO upload of 0x6041", bus="arm", node=3,
                              device="node 3 (joint3)", hint="is the drive powered?")
    assert (fault.bus, fault.node, fault.device) == ("arm", 3, "node 3 (joint3)")
    assert str(fault) == ("error: no answer to the SDO upload of 0x6041\n"
                          "    what to do: is the drive powered?")
    assert (BusError.single("bus 'arm' is gone").bus, EnableError.single("x").drives) == (
        None, ())


def test_a_boot_timeout_names_the_silent_drives_and_is_a_timeout_error():
    timeout = BootTimeout.single("node 1 (joint1); node 2 (joint2): not heard within 5 s",
                                 timeout=5.0, drives=("node 1 (joint1)", "node 2 (joint2)"),
                                 bus="arm")
    assert isinstance(timeout, BringUpError) and isinstance(timeout, TimeoutError)
    assert timeout.timeout == 5.0 and timeout.bus == "arm"
    assert timeout.drives == ("node 1 (joint1)", "node 2 (joint2)")
    assert timeout.device == "node 1 (joint1)"
    with pytest.raises(BringUpError):
        raise timeout
