"""The serial port a serial sensor speaks on: a pseudo-terminal hil creates (no root), its
slave end reached through a link at the configured path, so a pyserial reader opens it as it
opens a USB serial device (``serial.Serial("/tmp/hil-imu", 460800)``).

Like a USB serial device, it loses what it sends while no program has the port open (a
pseudo-terminal would keep it for the next one: stale samples), and what a reader leaves
unread past the terminal's buffer (an overrun); both are counted in :attr:`lost_bytes`.
A pseudo-terminal has no baud rate of its own: the config's is checked to carry the
sensor's stream (:mod:`hil.bus_config.sensor_entry`), and any rate a reader sets works.
"""

from __future__ import annotations

import os
import select
import termios
import tty
from pathlib import Path

from hil.errors import ConfigError
from hil.sensors.port import Port

#: where Linux's pseudo-terminals are: a dangling link to one is an earlier run's, replaced;
#: any other link is the user's, never touched
PTS = "/dev/pts/"


class PseudoTerminal(Port[bytes]):
    """A pseudo-terminal linked at ``link``; :meth:`write` sends, :meth:`close` removes it."""

    def __init__(self, link: Path, config: Path | None = None, line: int | None = None):
        """``config`` and ``line``: the bus config entry the port is made for (its errors
        name them)."""
        if link.is_symlink() and not link.exists() and os.readlink(link).startswith(PTS):
            link.unlink()       # left by a run that did not end cleanly: its terminal is gone
        elif link.is_symlink():
            raise ConfigError.single(f"the sensor port '{link}' is taken: it links to "
                                     f"{os.readlink(link)}", config, line,
                                     hint="another hil run may be serving it: stop that run, "
                                          "give this sensor another 'port', or remove the "
                                          "link if it is stale")
        elif link.exists():
            raise ConfigError.single(f"the sensor port '{link}' exists and is not a link",
                                     config, line, hint="give the sensor a 'port' path that is "
                                                        "free (hil makes a link there to its "
                                                        "terminal)")
        self._master, slave = os.openpty()
        self.device = os.ttyname(slave)
        tty.setraw(slave)                  # bytes as they are: no echo, no line editing
        os.close(slave)
        os.set_blocking(self._master, False)
        self._poll = select.poll()
        self._poll.register(self._master, select.POLLOUT)
        try:
            link.parent.mkdir(parents=True, exist_ok=True)
            os.symlink(self.device, link)
        except OSError as error:
            os.close(self._master)
            raise ConfigError.single(f"cannot make the sensor port '{link}': {error.strerror}",
                                     config, line, hint="give the sensor a 'port' path in a folder "
                                                "you can write") from None
        self.link = link
        self.lost_bytes = 0
        self._open = False

    def write(self, data: bytes) -> None:
        """Send ``data`` if a reader has the port open; lost (counted) otherwise or where the
        reader's buffer is full."""
        (_, events), = self._poll.poll(0)
        if events & select.POLLHUP:          # nobody has the slave end open
            if self._open:                   # forget what the last reader left unread
                termios.tcflush(self._master, termios.TCIOFLUSH)
                self._open = False
            self.lost_bytes += len(data)
            return
        self._open = True
        try:
            sent = os.write(self._master, data)
        except BlockingIOError:
            sent = 0
        self.lost_bytes += len(data) - sent

    def close(self) -> None:
        """Close the terminal and remove its link (if it is still ours); once."""
        if self._master < 0:
            return
        try:
            if os.readlink(self.link) == self.device:
                self.link.unlink()
        except OSError:
            pass
        os.close(self._master)
        self._master = -1
