"""Names that become Zenoh key expressions address one robot, one channel: a wildcard in
them is refused where it is given (issue 43: `hil send '**'` addressed every robot on the
network and moved the ur3; a channel name that was no key expression crashed `hil sim`)."""

from __future__ import annotations

import pytest

from conftest import TESTS
from hil.bus_config import load_bus_config
from hil.cli import main
from hil.errors import HilError
from hil.zenoh_session import key_name_problem


@pytest.mark.parametrize("name", ["**", "*", "ur3/*", "ur3$*", "a?b", "x#y", ""])
def test_a_robot_name_with_a_wildcard_or_separator_is_no_key_name(name):
    assert key_name_problem(name)


@pytest.mark.parametrize("name", ["ur3", "pigot", "go1_v2", "arm-left.3"])
def test_plain_robot_names_are_key_names(name):
    assert key_name_problem(name) is None


@pytest.mark.parametrize("command", [["send", "**", "--joint", "joint2", "--to", "0.3",
                                      "--in", "1s"], ["reset", "hil/*"]])
def test_send_and_reset_refuse_a_robot_name_that_addresses_more_than_one(command, capsys):
    assert main(command) == 1
    assert "wildcards" in capsys.readouterr().err


def test_a_channel_with_a_wildcard_is_refused_naming_its_line(tmp_path):
    text = (TESTS / "fixtures" / "damiao_one_axis.yaml").read_text()
    config = tmp_path / "wild.yaml"
    config.write_text(text.replace("robot: damiao_one_axis.urdf",
                                   f"robot: {TESTS / 'fixtures' / 'damiao_one_axis.urdf'}")
                      .replace("channel: damiao/arm", "channel: damiao/**"))
    with pytest.raises(HilError, match=r"channel 'damiao/\*\*': it holds '\*'") as raised:
        load_bus_config(config)
    assert f"{config}:" in str(raised.value)
