"""Hostile files named to the commands that read logs and recordings and write runs (issue 65
item 12; issue 64 item 18): `hil replay`'s logs and `hil review`'s recordings go through a
bounded reader (a regular file, checked before a byte is read; a size, frame and line bound,
hil.replay.files' module doc); every file a command writes is checked before the run begins
and what it replaces is named (hil.cli.written_files). Nothing here may block: a FIFO is
refused before it is opened for reading, and /dev/zero before a byte of it is read."""

from __future__ import annotations

import os
import re
from pathlib import Path

import can
import can.io.mf4
import pytest

from hil.cli import build_parser, main
from hil.errors import HilError
from hil.replay import files as log_reading
from hil.replay.files import not_whole, read_log

DEVICES = pytest.mark.skipif(not (os.path.exists("/dev/zero") and os.path.exists("/dev/full")),
                             reason="no /dev/zero or /dev/full here")


def _log(path: Path, frames: int = 200) -> Path:
    with can.Logger(str(path)) as writer:
        for n in range(frames):
            writer.on_message_received(can.Message(timestamp=1.0 + n * 0.002,
                                                   arbitration_id=0x181, data=bytes(8),
                                                   channel=1))
    return path


def _said(capsys, *argv: str) -> tuple[int, str]:
    status = main(list(argv))
    captured = capsys.readouterr()
    return status, captured.out + captured.err


# --- reading: hil replay's logs ---------------------------------------------------------------

@pytest.mark.parametrize("suffix", [".log", ".blf", ".asc"])
def test_a_fifo_named_as_a_log_is_refused_without_waiting_for_a_writer(tmp_path, suffix):
    """A FIFO .log hung `hil replay` (python-can opened it and waited for a writer)."""
    fifo = tmp_path / f"bus{suffix}"
    os.mkfifo(fifo)
    with pytest.raises(HilError, match=re.escape(f"CAN log '{fifo}' is not a regular file")):
        list(read_log(fifo))
    folder = tmp_path / "bench"                      # a folder's file alike
    folder.mkdir()
    os.mkfifo(folder / f"arm{suffix}")
    with pytest.raises(HilError, match="is not a regular file"):
        list(read_log(folder))


@DEVICES
@pytest.mark.parametrize("suffix", [".log", ".csv", ".trc", ".asc", ".blf"])
def test_a_device_named_as_a_log_is_refused_before_a_byte_is_read(tmp_path, suffix):
    """/dev/zero as a .log, .csv, .trc or .asc: python-can read its one endless line until
    MemoryError."""
    log = tmp_path / f"zero{suffix}"
    log.symlink_to("/dev/zero")
    with pytest.raises(HilError, match="is not a regular file"):
        list(read_log(log))
    assert not_whole(log) is None                    # read_log says what is wrong


@pytest.mark.skipif(can.io.mf4.asammdf is not None, reason="asammdf installed: MF4 is read")
def test_an_mf4_log_without_asammdf_is_refused_by_name_with_the_formats_read(tmp_path, capsys):
    """python-can reads MF4 only with asammdf: `hil replay x.mf4` gave NotImplementedError."""
    log = tmp_path / "run.mf4"
    log.write_bytes(b"MDF     4.10    ")
    status, said = _said(capsys, "replay", str(log), "ur3")
    assert status == 1 and "asammdf" in said and "Traceback" not in said, said
    assert ".blf, .asc, .log, .csv, .trc" in said, said


@pytest.mark.parametrize("suffix", [".db", ".asc.gz", ".mp3"])
def test_a_format_hil_does_not_read_is_named_with_what_to_do(tmp_path, suffix):
    log = tmp_path / f"run{suffix}"
    log.write_bytes(b"not read")
    with pytest.raises(HilError, match=r"give a \.blf, \.asc"):
        list(read_log(log))


def test_a_log_over_the_size_bound_is_refused_naming_it(tmp_path, monkeypatch):
    log = _log(tmp_path / "big.asc")
    monkeypatch.setattr(log_reading, "MAX_LOG_BYTES", 1024)
    with pytest.raises(HilError, match=r"CAN log '.*big\.asc' is .* KiB, over the 1 KiB hil "
                                       r"reads"):
        list(read_log(log))


def test_a_log_over_the_frame_bound_is_refused_naming_it_and_what_to_do(tmp_path, monkeypatch):
    log = _log(tmp_path / "long.blf")
    monkeypatch.setattr(log_reading, "MAX_LOG_FRAMES", 150)
    with pytest.raises(HilError, match=r"'.*long\.blf' holds over 150 frames") as refused:
        list(read_log(log))
    assert "replay a stretch of it" in str(refused.value)


def test_a_text_log_line_over_the_bound_is_refused_not_read_whole(tmp_path, monkeypatch):
    """A text log with no line end was one string of the whole file (/dev/zero's: endless)."""
    log = tmp_path / "one_line.log"
    log.write_text("(1.000000) can0 181#00\n" + "x" * 500)
    monkeypatch.setattr(log_reading, "MAX_LINE_CHARS", 100)
    with pytest.raises(HilError, match="has a line of over 100 characters"):
        list(read_log(log))


def test_a_blf_object_over_the_bound_is_damage_not_a_read_of_that_size(tmp_path, monkeypatch):
    log = _log(tmp_path / "run.blf", frames=2000)
    monkeypatch.setattr(log_reading, "MAX_OBJECT_BYTES", 64)
    with pytest.raises(HilError, match=r"'.*run\.blf' is damaged: at byte \d+ it gives a length"):
        list(read_log(log))


def test_a_log_within_the_bounds_is_read_whole(tmp_path):
    for suffix in (".blf", ".asc", ".log", ".csv", ".trc"):
        assert len(list(read_log(_log(tmp_path / f"run{suffix}")))) == 200, suffix


# --- reading: hil review's recordings ---------------------------------------------------------

def test_a_fifo_or_a_device_named_as_a_recording_is_refused_by_review(tmp_path, capsys):
    """`hil review` said "no recording" of a FIFO (and rerun, given one, waits for a writer)."""
    fifo = tmp_path / "run.rrd"
    os.mkfifo(fifo)
    status, said = _said(capsys, "review", str(fifo), "--no-viewer")
    assert status == 1 and f"recording '{fifo}' is not a regular file" in said, said
    os.mkfifo(tmp_path / "other-0001.rrd")           # a segment alike
    status, said = _said(capsys, "review", str(tmp_path / "other.rrd"), "--no-viewer")
    assert status == 1 and "other-0001.rrd' is not a regular file" in said, said


def test_a_recording_over_the_size_bound_is_refused_naming_it(tmp_path, monkeypatch):
    from hil.visualisation import review as reviewing

    recording = tmp_path / "run.rrd"
    recording.write_bytes(b"x" * 5000)
    monkeypatch.setattr(reviewing, "MAX_RECORDING_BYTES", 4096)
    with pytest.raises(HilError, match=r"recording '.*run\.rrd' is 4\.88 KiB, over the 4 KiB"):
        reviewing.review([recording])


# --- writing: checked before the run, what is replaced named -----------------------------------

def _unwritable(tmp_path: Path) -> list[Path]:
    """Places no run can be kept in: a folder, a file under a file, /dev/full where present."""
    (tmp_path / "a_folder").mkdir()
    (tmp_path / "a_file").write_text("")
    places = [tmp_path / "a_folder", tmp_path / "a_file" / "run.rrd"]
    return places + ([Path("/dev/full")] if os.path.exists("/dev/full") else [])


def test_replay_record_to_a_place_no_file_can_be_is_refused_before_the_log_is_read(
        tmp_path, capsys):
    """`--record /dev/full` or a folder: rerun's RuntimeError traceback at the replay's end."""
    log = tmp_path / "empty.blf"
    log.write_bytes(b"")                             # refused too, but only after --record
    for place in _unwritable(tmp_path):
        status, said = _said(capsys, "replay", str(log), "ur3", "--record", str(place))
        assert status == 1 and f"--record '{place}'" in said and "Traceback" not in said, said


def test_replay_record_names_the_file_it_replaces(tmp_path, capsys):
    """Issue 64 item 18: `hil replay --record` replaced a file without a word."""
    record = tmp_path / "replayed.rrd"
    record.write_bytes(b"r" * 1_500_000)
    (tmp_path / "replayed-0001.rrd").write_bytes(b"s")   # hil review would read it instead
    status, said = _said(capsys, "replay", str(tmp_path / "missing.blf"), "ur3",
                         "--record", str(record))
    assert f"hil replay: replacing {record} (1.5 MB, " in said, said
    assert "1 segment(s) replayed-0001.rrd" in said and not (tmp_path / "replayed-0001.rrd"
                                                             ).exists()


def test_viz_save_or_can_log_to_a_place_no_file_can_be_is_refused_before_the_run(
        tmp_path, capsys):
    for place in _unwritable(tmp_path):
        for option in ("--save", "--can-log"):
            status, said = _said(capsys, "viz", "ur3", "--normal-scheduling", option,
                                 str(place), *(["--save", str(tmp_path / "ok.rrd")]
                                               if option == "--can-log" else []))
            assert status == 1 and f"{option} '{place}'" in said, said


def test_viz_save_names_the_file_it_replaces(tmp_path):
    """Issue 64 item 18: `hil viz --save` replaced a file without a word."""
    from hil.cli.viz import _sinks

    save, can_log = tmp_path / "run.rrd", tmp_path / "run.blf"
    save.write_bytes(b"v" * 2_000_000)
    can_log.write_bytes(b"c" * 100_000)
    argv = ["viz", "ur3", "--save", str(save), "--can-log", str(can_log)]
    sinks = _sinks(build_parser(argv).parse_args(argv))
    assert f"replacing {save} (2.0 MB, " in sinks.described
    assert f"{can_log} (0.1 MB, " in sinks.described


def test_up_outputs_in_a_place_no_file_can_be_are_refused_before_anything_is_replaced(
        tmp_path):
    from hil.cli.up.outputs import replace_previous

    logs = tmp_path / "run.logs"
    kept = tmp_path / "run-0001.rrd"
    kept.write_bytes(b"a previous run's segment")
    for place in _unwritable(tmp_path):
        with pytest.raises(HilError, match=re.escape(f"--save '{place}'")):
            replace_previous(place, tmp_path / "run.can.blf", logs)
        with pytest.raises(HilError, match=re.escape(f"--can-log '{place}'")):
            replace_previous(tmp_path / "run.rrd", place, logs)
    assert kept.exists()                             # refused before a segment was removed
    logs.write_text("a file where the logs' folder goes")
    with pytest.raises(HilError, match="process logs' folder .* is a file"):
        replace_previous(tmp_path / "run.rrd", tmp_path / "run.can.blf", logs)
