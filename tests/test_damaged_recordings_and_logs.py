"""Recordings and CAN logs damaged as a crash or a bad copy leaves them (issue 43): ``hil
review`` lists what the whole segments hold and names the damaged one with rerun's reason;
``hil replay``'s log reader gives the frames it can read or a clear error, never a
traceback."""

from __future__ import annotations

import random
import subprocess
import sys
import time

import can
import pytest
import rerun as rr

from hil.errors import HilError
from hil.replay import not_whole
from hil.replay.log import read_log


def _segment(path, fault: str) -> None:
    """A segment as the recorder writes one: a fault on the diagnostics' timelines."""
    recording = rr.RecordingStream("hil", recording_id="one-run")
    recording.save(path)
    recording.send_columns("/diagnostics",
                           indexes=[rr.TimeColumn("wall_time", timestamp=[time.time()])],
                           columns=rr.TextLog.columns(text=[fault], level=[rr.TextLogLevel.ERROR]))
    recording.flush()
    recording.disconnect()


@pytest.fixture
def three_segments(tmp_path):
    for n in (1, 2, 3):
        _segment(tmp_path / f"run-000{n}.rrd", f"fault in segment {n}")
    return tmp_path


def _review(recording):
    return subprocess.run([sys.executable, "-m", "hil", "review", str(recording), "--no-viewer"],
                          capture_output=True, text=True, timeout=120)


@pytest.mark.parametrize("damage", ["cut in half", "cut to nothing", "not a recording"])
def test_review_lists_the_whole_segments_and_names_the_damaged_one(three_segments, damage):
    last = three_segments / "run-0003.rrd"
    whole = last.read_bytes()
    last.write_bytes({"cut in half": whole[:len(whole) // 2], "cut to nothing": b"",
                      "not a recording": b"\x8c\xb9" * 100}[damage])
    reviewed = _review(three_segments / "run.rrd")
    assert reviewed.returncode == 0 and "Traceback" not in reviewed.stderr, reviewed.stderr
    assert "3 file(s)" in reviewed.stdout
    assert "fault in segment 1" in reviewed.stdout and "fault in segment 2" in reviewed.stdout
    assert "run-0003.rrd damaged: " in reviewed.stdout


def test_review_of_files_none_of_which_is_a_recording_is_an_error(tmp_path):
    (tmp_path / "run.rrd").write_bytes(b"not rerun's")
    reviewed = _review(tmp_path / "run.rrd")
    assert reviewed.returncode == 1 and "Traceback" not in reviewed.stderr
    assert "no file of it is a rerun recording" in reviewed.stderr


def test_review_of_whole_segments_names_no_damage(three_segments):
    reviewed = _review(three_segments / "run.rrd")
    assert reviewed.returncode == 0, reviewed.stderr
    assert "damaged" not in reviewed.stdout and "3 fault(s)" in reviewed.stdout


LOG_FORMATS = ("blf", "asc", "log", "csv", "trc")


def _damaged(data: bytes, rng: random.Random) -> bytes:
    """``data`` cut short, with bytes changed, or with bytes put in: what a crash, a bad
    disk or a bad copy leaves."""
    damaged = bytearray(data)
    kind = rng.randrange(3)
    if kind == 0:
        return bytes(damaged[:rng.randrange(len(damaged))])
    if kind == 1:
        for _ in range(rng.randint(1, 20)):
            damaged[rng.randrange(len(damaged))] = rng.randrange(256)
        return bytes(damaged)
    at = rng.randrange(len(damaged))
    return bytes(damaged[:at] + rng.randbytes(rng.randint(1, 50)) + damaged[at:])


@pytest.mark.parametrize("suffix", LOG_FORMATS)
def test_a_damaged_can_log_gives_its_frames_or_a_clear_error(tmp_path, suffix):
    """60 seeded damages of a log of 2000 frames in each format python-can writes (a BLF's
    zlib container and object headers among them)."""
    log = tmp_path / f"whole.{suffix}"
    with can.Logger(str(log)) as writer:
        for n in range(2000):
            writer.on_message_received(can.Message(timestamp=1.0 + n * 0.002,
                                                   arbitration_id=0x180 + n % 6,
                                                   data=n.to_bytes(4, "little"), channel=1))
    whole = log.read_bytes()
    rng = random.Random(43)
    for trial in range(60):
        damaged = tmp_path / f"damaged.{suffix}"
        damaged.write_bytes(_damaged(whole, rng))
        try:
            frames = sum(1 for _ in read_log(damaged))
        except HilError as exc:
            assert "damaged" in str(exc) or "cannot read" in str(exc), exc
        else:
            assert 0 <= frames <= 2100, (trial, frames)


def test_a_cut_blf_is_named_not_whole_and_a_closed_one_is_not(tmp_path):
    """python-can reads a cut BLF up to its last whole frame without a word; its header's
    file size (written at close) tells hil replay to say so."""
    log = tmp_path / "run.blf"
    with can.Logger(str(log)) as writer:
        for n in range(3000):
            writer.on_message_received(can.Message(timestamp=1.0 + n * 0.002,
                                                   arbitration_id=0x181, data=bytes(8)))
    assert not_whole(log) is None
    log.write_bytes(log.read_bytes()[:len(log.read_bytes()) // 2])
    assert "cut off, or never closed" in not_whole(log)
