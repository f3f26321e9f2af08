"""A command whose output's reader leaves (`hil ... | head`, a harness that died): it stops
through its own SIGTERM handling where it has one, never with a traceback, and ends with
status 141 (hil.cli.output). The processes of `hil up` in that case: tests/test_up.py."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

#: a child writing to a pipe whose reader has gone, under the guard; it reports on stderr
WRITER = """
import io, json, os, signal, sys, time
from hil.cli.output import ReaderGone, guarded_output
stops = []
if sys.argv[1] == "handled":
    signal.signal(signal.SIGTERM, lambda *_: stops.append(time.monotonic()))
read_end, write_end = os.pipe()
os.close(read_end)
report = sys.stderr
sys.stdout = io.TextIOWrapper(os.fdopen(write_end, "wb"), line_buffering=True)
with guarded_output():
    for _ in range(3):
        print("a line nobody reads", flush=True)
    time.sleep(0.2)                  # a signal's handler runs between two bytecodes
    target = os.readlink(f"/proc/self/fd/{write_end}")
json.dump({"stops": len(stops), "left": ReaderGone.left, "target": target}, report)
"""


@pytest.mark.parametrize("handling", ["handled", "default"])
def test_a_reader_that_leaves_stops_a_command_once_and_silences_the_stream(handling):
    done = subprocess.run([sys.executable, "-c", WRITER, handling], capture_output=True,
                          text=True, timeout=60)
    assert done.returncode == 0, done.stderr          # never killed by SIGTERM's default
    report = json.loads(done.stderr.strip().splitlines()[-1])
    assert report["left"] and report["target"] == "/dev/null"
    # the command's own stop, once however many writes failed; none where it has no handler
    assert report["stops"] == (1 if handling == "handled" else 0)


@pytest.mark.parametrize("command, under_way", [
    (["describe", "ur3"], False),                  # no SIGTERM handling: finishes silently
    (["sim", "ur3", "--duration", "30s"], True),   # stops as on SIGTERM, at its next line
], ids=["describe", "sim"])
def test_a_command_whose_reader_leaves_ends_141_without_a_traceback(command, under_way):
    process = subprocess.Popen([sys.executable, "-m", "hil", *command], stdout=subprocess.PIPE,
                               stderr=subprocess.PIPE, text=True)
    try:
        if under_way:
            process.stdout.readline()     # its first line: its stop handling is in place
        process.stdout.close()            # the reader gone before its next write
        err = process.stderr.read()
        process.wait(timeout=60)
    finally:
        if process.poll() is None:
            process.kill()
            process.wait()
    assert process.returncode == 141, err
    assert "Traceback" not in err and "Exception ignored" not in err, err
