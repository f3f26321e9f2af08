"""The floor's answering process (``python -m hil.bench.responder SPEC``): on each bus, the
cycle's answers when its trigger frame arrives; python-can only, no hil drive.

A module of its own: run as ``-m`` from inside the package it would be imported twice (the
package's ``__init__`` imports :mod:`hil.bench.floor`)."""

from __future__ import annotations

import json
import os
import signal
import sys
import time

import can

from hil.realtime import enter_real_time


def respond(spec: dict) -> None:
    """The floor's answering process: on each bus, the answers on the trigger frame; in
    real time as ``hil sim`` runs there (``spec["real_time"]``), else scheduled normally as
    in lock-step; on ``spec["cpus"]`` either way."""
    if spec["real_time"]:
        enter_real_time(cpus=set(spec["cpus"]) or None)
    elif spec["cpus"]:      # as `hil sim --lock-step --cpus`: this process and its threads
        os.sched_setaffinity(0, set(spec["cpus"]))
    buses = []
    for bus_spec in spec["buses"]:
        bus = can.Bus(interface="zenoh", channel=bus_spec["channel"], listen=[spec["endpoint"]])
        answers = [can.Message(arbitration_id=i, data=bytes(n), is_extended_id=extended)
                   for i, n, extended in bus_spec["answers"]]

        def answer(msg: can.Message, bus=bus, answers=answers,
                   trigger=bus_spec["trigger"]) -> None:
            if msg.arbitration_id == trigger:
                for frame in answers:
                    bus.send(frame)

        bus.deliver_to([answer])
        buses.append(bus)
    print("ready", flush=True)
    try:
        time.sleep(spec["seconds"])
    finally:
        for bus in buses:
            bus.shutdown()


if __name__ == "__main__":
    signal.signal(signal.SIGTERM, lambda *_: sys.exit(0))
    respond(json.loads(sys.argv[1]))
