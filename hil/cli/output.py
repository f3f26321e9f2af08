"""Standard output and error for the commands, whose reader may leave.

`hil up | head -1`, a test harness killed mid-run, a terminal multiplexer gone: the next
write to the pipe fails with EPIPE. Python ignores SIGPIPE and raises BrokenPipeError in
whichever thread wrote, at whatever point it wrote: `hil sim`'s status thread died with a
traceback, and `hil up`, whose shutdown prints before it stops its children, left sim and
control running and then waited for good on Zenoh's threads at exit (seen 2026-11-29).

Here a reader that leaves ends the command as SIGPIPE ends a Unix filter, but through the
command's own stop: the stream is pointed at /dev/null (later writes go nowhere and never
fail), and where the command handles SIGTERM (sim, control, viz, up, router: drives
disabled, children stopped, sessions closed; send while it waits for its goal: the goal
cancelled) it gets one, as if the user had sent it. A
command that does not handle SIGTERM (short ones: describe, ls ...) finishes
without output; SIGTERM's default action would end it without any of its clean-up. Either
way the exit status is 141 (128 + SIGPIPE), as a shell reports a filter ended by SIGPIPE.
"""

from __future__ import annotations

import os
import signal
import sys
from collections.abc import Iterator
from contextlib import contextmanager

#: the exit status of a command whose reader left (128 + SIGPIPE)
READER_LEFT_STATUS = 128 + 13


class ReaderGone:
    """Whether a reader of this process' output left (once is enough: one stop)."""

    left = False


class GuardedStream:
    """A text stream (sys.stdout, sys.stderr) whose writes never raise BrokenPipeError: the
    first one stops the command (the module doc) and sends the rest to /dev/null. Everything
    else is the stream's own."""

    def __init__(self, stream):
        self._stream = stream

    def write(self, text: str) -> int:
        try:
            return self._stream.write(text)
        except BrokenPipeError:
            self._reader_left()
            return len(text)

    def flush(self) -> None:
        try:
            self._stream.flush()
        except BrokenPipeError:
            self._reader_left()

    def __getattr__(self, name: str):
        return getattr(self._stream, name)

    def _reader_left(self) -> None:
        # the buffered text that failed is written again, to /dev/null, by the next flush
        to_devnull(self._stream)
        if ReaderGone.left:
            return
        ReaderGone.left = True
        if callable(signal.getsignal(signal.SIGTERM)):     # the command's own stop
            os.kill(os.getpid(), signal.SIGTERM)


def to_devnull(stream) -> None:
    """Point the file descriptor under ``stream`` at /dev/null (a stream of no file, as a
    test's capture: nothing)."""
    try:
        descriptor = stream.fileno()
    except (OSError, ValueError):
        return
    devnull = os.open(os.devnull, os.O_WRONLY)
    os.dup2(devnull, descriptor)
    os.close(devnull)


@contextmanager
def guarded_output() -> Iterator[None]:
    """sys.stdout and sys.stderr guarded while the block runs (not twice: a command run
    from within another, as the tests run them, keeps the outer guard)."""
    if isinstance(sys.stdout, GuardedStream):
        yield
        return
    streams = sys.stdout, sys.stderr
    sys.stdout, sys.stderr = GuardedStream(sys.stdout), GuardedStream(sys.stderr)
    ReaderGone.left = False
    try:
        yield
    finally:
        for stream in (sys.stdout, sys.stderr):     # what is still buffered meets its reader
            stream.flush()                          # here, not in the interpreter's exit
        sys.stdout, sys.stderr = streams
