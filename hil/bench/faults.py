"""Fault detection: each fault kind injected into a running stack, and how soon the
controller reports it."""

from __future__ import annotations

import time
from collections.abc import Callable

from hil.bus_config import SystemConfig
from hil.can.faults import DriveFaultKind, FrameFault, FrameFaultKind
from hil.bench.settings import DID_NOT_START
from hil.simulator import Simulator
from hil.stack import StackDidNotStart, running_stack
from hil.realtime.timing import REAL_TIME


def fault_detection(config: SystemConfig, timeout: float = 3.0) -> list[dict]:
    """Inject each fault kind into a running stack; how soon does the controller say so?"""
    first = config.buses[0]
    drive = first.drives[1]         # by its config entry: an LSS master may change its id
    kinds = {
        "drop every frame": lambda sim, buses: buses[first.name].add(
            FrameFault(FrameFaultKind.DROP, first.name, 1.0)),
        "delay answers 200 ms": lambda sim, buses: buses[first.name].add(
            FrameFault(FrameFaultKind.DELAY, first.name, 1.0, 0.2)),
        "corrupt payload bits": lambda sim, buses: buses[first.name].add(
            FrameFault("corrupt", first.name, 1.0)),
        "silence a drive": lambda sim, buses: sim.inject(DriveFaultKind.SILENCE,
                                                          sim.configured(drive)),
        "raise a drive fault": lambda sim, buses: sim.inject(DriveFaultKind.FAULT,
                                                              sim.configured(drive)),
    }
    rows = []
    for kind, inject in kinds.items():
        try:
            rows.append({"fault": kind, **_detection(config, inject, timeout)})
        except StackDidNotStart as failure:
            rows.append({"fault": kind, "detected": False, "detection_ms": None,
                         "first_report": None, DID_NOT_START: str(failure)})
    return rows


def _detection(config: SystemConfig, inject: Callable[[Simulator, dict], object],
               timeout: float) -> dict:
    with running_stack(config, REAL_TIME, injectable=True) as stack:
        time.sleep(0.2)
        reported = len(stack.node.faults)
        started = time.perf_counter()
        inject(stack.sim, stack.sim_buses)
        while len(stack.node.faults) == reported and time.perf_counter() - started < timeout:
            time.sleep(0.0005)
        elapsed = time.perf_counter() - started
        detected = len(stack.node.faults) > reported
        return {"detected": detected, "detection_ms": elapsed * 1e3 if detected else None,
                "first_report": str(stack.node.faults[reported]) if detected else None}
