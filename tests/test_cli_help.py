"""Every ``hil`` sub-command's ``--help`` prints its help and exits 0 (issue 46: `hil replay
--help` ended in a traceback, a `%` in a help string that argparse %-formats)."""

from __future__ import annotations

import re

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
    assert all(re.search(rf"^    {name}(\s|$)", printed, re.MULTILINE) for name in COMMANDS), \
        printed


def _options(command: str):
    from hil.cli import build_parser

    parser = build_parser([command])
    (sub,) = [a for a in parser._actions if a.dest == "command"]      # argparse's own table
    return sub.choices[command]._actions


@pytest.mark.parametrize("command", sorted(COMMANDS))
def test_every_time_option_takes_one_duration_syntax(command):
    """Issue 46: durations were written four ways (`2s|500ms`, `S`, "seconds", `10m`): every
    option that takes a time takes `500ms`, `2s`, `10min` and a bare number of seconds."""
    from hil.cli import common

    for action in _options(command):
        if action.metavar in ("S", "SECONDS", "DURATION") or action.dest in (
                "timeout", "duration", "status_period", "boot_timeout", "seconds", "soak"):
            assert action.metavar == "TIME", (command, action.option_strings)
            assert action.type in (common.duration, common.duration_or_zero), (
                command, action.option_strings)


def test_a_duration_is_read_in_every_unit_and_refused_with_the_forms():
    from hil.durations import parse_duration

    assert [parse_duration(t) for t in ("500ms", "2s", "1.5", "10min", "10m", "1h")] == [
        0.5, 2.0, 1.5, 600.0, 600.0, 3600.0]
    for wrong in ("2 parsecs", "-1s", "nan", "", "1e999h"):
        with pytest.raises(ValueError, match="duration"):
            parse_duration(wrong)


def test_a_wrong_duration_is_an_argparse_error_not_a_traceback(capsys):
    with pytest.raises(SystemExit) as ended:
        main(["send", "ur3", "--joint", "joint2", "--to", "0.1", "--in", "2 parsecs"])
    assert ended.value.code == 2
    assert "--in: '2 parsecs' is not a duration: give e.g. 500ms" in capsys.readouterr().err


def test_output_cut_short_by_its_reader_ends_without_a_traceback(monkeypatch):
    """`hil check ur3 | head -1`: the reader left; hil ends quietly (141, as a shell says
    for SIGPIPE) instead of a BrokenPipeError traceback."""
    import os

    read_end, write_end = os.pipe()
    os.close(read_end)                                  # the reader is gone
    with os.fdopen(write_end, "w", buffering=1) as stdout:
        monkeypatch.setattr("sys.stdout", stdout)
        assert main(["check", "ur3"]) == 141
