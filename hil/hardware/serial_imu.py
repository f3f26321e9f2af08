"""The controller's side of a serial IMU: its port opened as a USB serial device's is,
read without blocking at each control cycle, its packets decoded as the maker's sample code
decodes them.

The port is taken exclusively (``flock``, as pyserial's ``exclusive=True`` and the
``witmotion`` reader take it): two programs reading one serial port each get part of its
bytes, so whichever opens it second is told so, not fed half the samples. Until it opens,
and after it goes away (the bench stopped), it is tried again every RETRY seconds.
"""

from __future__ import annotations

import errno
import fcntl
import os
import time
import tty

from hil.bus_config.sensor_types import ImuConfig
from hil.hardware.sensor_states import ImuState
from hil.protocols import wit

#: how often a port that is not there (yet), or held by another program, is tried (s)
RETRY = 1.0
#: the most bytes a cycle reads: 200 Hz of four packets is 8.8 kB/s, a cycle's share a few
#: hundred bytes; the rest waits for the next cycle
READ_LIMIT = 4096


class SerialImu:
    """One IMU of the bus config, read off its serial port."""

    def __init__(self, config: ImuConfig, clock=time.time):
        self.config = config
        self._clock = clock
        self._reader = wit.PacketReader(config.outputs)
        self._fd = -1
        self._next_try = 0.0
        #: why the port is not read now (None: it is)
        self.problem: str | None = "not opened yet"

    def poll(self) -> list[ImuState]:
        """The samples that arrived since the last call (none while the port is closed)."""
        if self._fd < 0 and not self._open():
            return []
        try:
            data = os.read(self._fd, READ_LIMIT)
        except BlockingIOError:
            return []
        except OSError as error:        # EIO: the simulator closed its end
            self._close(f"the port went away ({error.strerror})")
            return []
        if not data:
            return []
        now = self._clock()
        return [ImuState(self.config.name, self.config.link, now, reading)
                for reading in self._reader.feed(data)]

    def _open(self) -> bool:
        now = time.monotonic()
        if now < self._next_try:
            return False
        self._next_try = now + RETRY
        port = str(self.config.port)
        try:
            fd = os.open(port, os.O_RDONLY | os.O_NOCTTY | os.O_NONBLOCK)
        except OSError as error:
            self.problem = f"cannot open {port}: {error.strerror}"
            return False
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            tty.setraw(fd)
        except OSError as error:
            os.close(fd)
            self.problem = (f"{port} is held by another program" if error.errno in (
                errno.EWOULDBLOCK, errno.EAGAIN) else f"{port}: {error.strerror}")
            return False
        self._fd, self.problem = fd, None
        return True

    def _close(self, problem: str) -> None:
        if self._fd >= 0:
            os.close(self._fd)
        self._fd, self.problem = -1, problem

    def close(self) -> None:
        """Release the port."""
        self._close("closed")

