"""The master's watch over its axes: faults and silences found each cycle and reported once,
and the fault reset that brings the axes back (a rebooted drive configured again)."""

from __future__ import annotations

import threading
import time

from hil.errors import HilError
from hil.hardware.axis import Axis, AxisFault, FaultKind
from hil.hardware.exchange import MISSED_ANSWER_LIMIT, CycleExchange, missed_too_many


class FaultWatch:
    """What is wrong with the axes of ``exchange``: each fault or silence is queued for
    :meth:`faults` once per drive and kind, and every axis is stopped (:attr:`stopping`)
    until :meth:`reset`."""

    def __init__(self, exchange: CycleExchange):
        self._exchange = exchange
        self.axes = exchange.axes
        #: how long a drive may be unheard, its answers within the limit of missed ones (in
        #: lock-step a stalled sim is slow, not dead); a bring-up request waits as long (s)
        self.answer_silence_limit = MISSED_ANSWER_LIMIT * exchange.reply_timeout
        #: a fault was found: every axis is brought to rest
        self.stopping = False
        #: after a reset, until every axis follows setpoints again: they hold where they are
        self.recovering = False
        self._reset_cycle = 0          # the cycle reset() was called in
        self._reported: set[tuple[str, str]] = set()
        #: rebooted axes being configured again (a reset's), off the watch meanwhile
        self.configuring: set[Axis] = set()
        self._pending: list[AxisFault] = []

    # --- each cycle ---------------------------------------------------------------------

    def watch(self) -> None:
        """Report each axis' fault, silence and missed answers as of this cycle."""
        now = time.monotonic()
        cycle = self._exchange.cycle
        # a reset's first answers may be late ones, sampled before its commands reached the
        # drives: the states it walks the drives out of (FAULT, QUICK STOP) count once an
        # answer that late would be silence anyway
        settling = self.recovering and cycle - self._reset_cycle <= MISSED_ANSWER_LIMIT
        for axis in self.axes:
            if axis in self.configuring:
                continue
            # a silence is reported once per axis, not once per silent cycle; a drive's own
            # fault once per distinct message
            fault = None if settling else axis.fault(self.stopping)
            if fault is not None:
                self.report(axis.label, fault.message, fault)
            silence = now - axis.last_heard
            if silence > self.answer_silence_limit and silence > axis.silence_limit:
                self.report(axis.label, "heartbeat", axis.found(
                    FaultKind.SILENT, f"is silent: not heard for {silence * 1e3:.0f} ms",
                    silent_for=silence))
            if missed_too_many(axis, cycle):
                missed = cycle - axis.feedback.cycle
                self.report(axis.label, "answer", axis.found(
                    FaultKind.SILENT, f"is silent: no answer for {missed} cycles",
                    silent_for=missed * self._exchange.reply_timeout))

    def settle(self) -> None:
        """A reset is over once nothing stops the axes, none is being configured and every
        one follows setpoints."""
        if (self.recovering and not self.stopping and not self.configuring
                and all(a.enabled for a in self.axes)):
            self.recovering = False

    def report(self, subject: str, what: str, fault: AxisFault) -> None:
        """Queue a fault for :meth:`faults` (once per subject and what) and stop every axis."""
        if (subject, what) not in self._reported:
            self._reported.add((subject, what))
            self._pending.append(fault)
            self.stopping = True

    def faults(self) -> list[AxisFault]:
        """The faults queued since the last call."""
        found, self._pending = self._pending, []
        return found

    def queued(self) -> list[AxisFault]:
        """The faults queued for :meth:`faults` (left there)."""
        return list(self._pending)

    @property
    def ready(self) -> bool:
        return not (self.stopping or self.recovering or self.configuring)

    # --- configuring and the fault reset -------------------------------------------------

    def configure(self, axis: Axis) -> None:
        """Configure a booted axis (its requests waiting as long as the watch waits for
        answers); its missed answers count from the cycle it is done in."""
        axis.request_timeout = self.answer_silence_limit
        axis.configure()
        axis.feedback.cycle = self._exchange.cycle

    def reset(self) -> None:
        """Forget what was reported and bring every axis back (:attr:`recovering`); a
        rebooted one is configured again meanwhile. A fault that persists (a silent drive,
        a fault still present) is reported again by the next cycles."""
        self.recovering = True
        self._reset_cycle = self._exchange.cycle
        self.stopping = False
        self._reported.clear()
        self._pending.clear()
        for axis in self.axes:
            axis.forget_faults()
        rebooted = [a for a in self.axes if a.rebooted and a not in self.configuring]
        if rebooted:
            # requests take round trips the control loop must not wait for: the cycles go on
            # (the drives hold), and the reset is done once these follow setpoints too
            self.configuring.update(rebooted)
            threading.Thread(target=self._configure_again, args=(rebooted,),
                             name="configure", daemon=True).start()

    def _configure_again(self, axes: list[Axis]) -> None:
        for axis in axes:
            try:
                self.configure(axis)
            except HilError as exc:
                self.report(axis.label, "configure", axis.found(
                    FaultKind.REBOOTED, f"booted again and could not be configured: {exc}"))
            finally:
                self.configuring.discard(axis)
