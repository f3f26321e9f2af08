#!/usr/bin/env python3
"""What the Zenoh transport's Python costs a process a cycle (a benchmark, not a test): one
message of BUSES sections of FRAMES classic frames each, as a process puts it (each bus' put
counted, its section encoded) and takes its answer in (decoded, each section's arrival
counted), with the installed form of hil.can's transport build (compiled where the install
compiled it) and with its Python source, in turns, ROUNDS times; the median of each.

    .venv/bin/python tools/transport_cost.py [BUSES] [FRAMES]

The G1 of ``hil init`` (29 Damiao drives on 6 buses) puts 6 sections of about 5 frames a
cycle each way: ``tools/transport_cost.py 6 5``.
"""

from __future__ import annotations

import importlib.util
import statistics
import sys
import time
from pathlib import Path

import hil.can.link_account
import hil.can.zenoh_wire
from hil.can.frame import Frame
from hil.compiled import COMPILED_TRANSPORT, is_compiled

ROUNDS = 7
MESSAGES = 5000


def sources() -> dict[str, object]:
    """The transport build's modules run from their Python sources, each importing the
    others' sources (not their installed forms), beside the installed ones."""
    installed = {name: sys.modules[name] for name in COMPILED_TRANSPORT}
    loaded = {}
    try:
        for name in COMPILED_TRANSPORT:        # in order: each imports those before it
            path = Path(installed[name].__file__).with_name(name.rpartition(".")[2] + ".py")
            spec = importlib.util.spec_from_file_location(name, path)
            loaded[name] = sys.modules[name] = importlib.util.module_from_spec(spec)
            spec.loader.exec_module(loaded[name])
    finally:
        sys.modules.update(installed)
    return loaded


def per_message(wire, account, buses: int, frames: int) -> float:
    """Microseconds a message: each bus' put counted and its section encoded, the message
    decoded, each section's arrival counted."""
    cycle = [Frame(0x10 + k, bytes(range(8))) for k in range(frames)]
    links = [account.LinkAccount(7, f"bus{k}") for k in range(buses)]
    channels = [f"robot/bus{k}" for k in range(buses)]
    start = time.perf_counter()
    for n in range(MESSAGES):
        now = 100.0 + 0.002 * n
        payload = b"".join(
            wire.encode_frames(channel, 99, 1 + frames * n, 1e9 + n, cycle,
                               link.sent(1 + frames * n, frames, now))
            for channel, link in zip(channels, links))
        for link, message in zip(links, wire.decode_frames(payload)):
            link.arrived(message, 1e9 + n + 1e-4, now + 3e-4)
    return (time.perf_counter() - start) / MESSAGES * 1e6


def main() -> int:
    buses, frames = (int(arg) for arg in (sys.argv[1:] + ["6", "5"])[:2])
    source = sources()
    forms = {"installed": (hil.can.zenoh_wire, hil.can.link_account),
             "source": (source["hil.can.zenoh_wire"], source["hil.can.link_account"])}
    times: dict[str, list[float]] = {name: [] for name in forms}
    for _ in range(ROUNDS):
        for name, (wire, account) in forms.items():
            times[name].append(per_message(wire, account, buses, frames))
    installed, source = (statistics.median(times[name]) for name in forms)
    form = "compiled" if is_compiled(hil.can.zenoh_wire) else "interpreted"
    print(f"{buses} sections of {frames} frames: installed ({form}) {installed:.1f} µs a "
          f"message, source {source:.1f} µs ({source / installed:.2f}x)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
