"""The fault reset: asked for from any thread, carried out by the control loop between
cycles, answered when every drive follows commands again or it fails."""

from __future__ import annotations

import queue
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field

from hil.controllers import JointTrajectoryController
from hil.hardware import AxisFault, HardwareInterface

#: how long a fault reset may take to bring every drive back (s)
RESET_TIMEOUT = 10.0


@dataclass
class FaultResetRequest:
    """A fault reset asked for from another thread; the control loop fills in the answer."""

    done: threading.Event = field(default_factory=threading.Event)
    succeeded: bool = False
    message: str = ""
    deadline: float = 0.0


class FaultReset:
    """The handshake of a fault reset: :meth:`request` from any thread blocks until the loop,
    calling :meth:`advance` once per cycle, has reset the drives' faults, brought them back
    and let the controller accept goals again, holding where the joints are; or until a
    fault persists or RESET_TIMEOUT passes. ``diagnose(level, message)`` reports the
    outcome as a diagnostic."""

    def __init__(self, hardware: HardwareInterface, controller: JointTrajectoryController,
                 diagnose: Callable[[str, str], None]):
        self._hardware, self._controller, self._diagnose = hardware, controller, diagnose
        self._requests: queue.SimpleQueue[FaultResetRequest] = queue.SimpleQueue()
        self._active: FaultResetRequest | None = None

    def request(self, timeout: float = RESET_TIMEOUT) -> tuple[bool, str]:
        """Ask for a reset and wait for it: (succeeded, what happened). Any thread."""
        request = FaultResetRequest()
        self._requests.put(request)
        if not request.done.wait(timeout + 1.0):
            return False, "the control loop did not answer (is it running?)"
        return request.succeeded, request.message

    def begin(self) -> None:
        """At the top of a cycle: take up a waiting request, if no reset is under way."""
        if self._active is not None or self._requests.empty():
            return
        self._active = self._requests.get_nowait()
        if self._controller.fault is None and self._hardware.ready:
            self._finish(True, "no fault to reset")      # and an active goal runs on
            return
        self._active.deadline = time.monotonic() + RESET_TIMEOUT
        self._hardware.reset_faults()

    def advance(self, faults: list[AxisFault]) -> None:
        """After the cycle's read: done when the hardware is ready, failed on a fault."""
        if self._active is None:
            return
        if faults:
            self._finish(False, "; ".join(map(str, faults)))
        elif self._hardware.ready:
            self._controller.clear_fault()
            self._finish(True, "every drive follows commands again; holding position")
            self._diagnose("OK", "fault reset: every drive follows commands again")
        elif time.monotonic() > self._active.deadline:
            self._finish(False, f"drives not back within {RESET_TIMEOUT:g} s")
            self._diagnose("ERROR", f"fault reset failed: drives not back within "
                                    f"{RESET_TIMEOUT:g} s")

    def close(self) -> None:
        """The loop ends: fail a reset under way, release every waiting request."""
        if self._active is not None:
            self._finish(False, "the controller is shutting down")
        while not self._requests.empty():
            self._requests.get_nowait().done.set()

    def _finish(self, succeeded: bool, message: str) -> None:
        request, self._active = self._active, None
        request.succeeded, request.message = succeeded, message
        request.done.set()
