"""Every ``hil`` sub-command's ``--help`` prints its help and exits 0 (issue 46: `hil replay
--help` ended in a traceback, a `%` in a help string that argparse %-formats)."""

from __future__ import annotations

import pytest

from hil.cli import COMMANDS, main


@pytest.mark.parametrize("command", sorted(COMMANDS))
def test_every_sub_command_help_runs(command, capsys):
    with pytest.raises(SystemExit) as ended:
        main([command, "--help"])
    assert ended.value.code == 0
    assert f"usage: hil {command}" in capsys.readouterr().out


def test_the_command_help_runs(capsys):
    with pytest.raises(SystemExit) as ended:
        main(["--help"])
    assert ended.value.code == 0
    printed = capsys.readouterr().out
    assert all(f"    {name} " in printed for name in COMMANDS), printed
