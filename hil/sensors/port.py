"""Where a simulated sensor's samples go (:class:`Port`): the seam between a sensor's
sampling (:mod:`.imu`) and its wire (:mod:`.serial_port`, :mod:`.can_port`,
:mod:`.polled_port`)."""

from __future__ import annotations

from typing import Protocol, TypeVar

#: what a wire carries of one sample (bytes, frames, the sample itself for a port that
#: encodes what its master asks for)
Payload = TypeVar("Payload", contravariant=True)


class Port(Protocol[Payload]):
    """Where a sensor's samples go, each as its wire carries it: a serial port's bytes, a CAN
    node's frames (or a test's capture)."""

    #: what the port is, in words (a pseudo-terminal: its /dev/pts path)
    device: str

    def write(self, data: Payload) -> None:
        """Send (or hold, for a master's next request) one sample."""

    def fall_silent(self) -> None:
        """The sensor has stopped. A port that streams needs nothing (no more samples are
        written to it); one that answers requests stops answering."""

    def close(self) -> None:
        """Leave the wire."""
