"""``hil bench --soak``: a trajectory repeated for a long time; drift, memory, missed cycles."""

from __future__ import annotations

import os
import time
from collections.abc import Callable

from hil.bench.settings import BenchSettings
from hil.bench.tracking import tracking_goal
from hil.bus_config import load_bus_config
from hil.controllers import GoalRejected
from hil.messaging import cdr
from hil.messaging.zenoh_api import TrajectoryActionClient, key
from hil.stack import running_stack
from hil.zenoh_session import close_all
from hil.realtime.timing import REAL_TIME


def run_soak(seconds: float, settings: BenchSettings, robot: str = "ur3",
             say: Callable[[str], None] = print) -> dict:
    """Repeat the tracking trajectory for ``seconds`` in real time; report the drift of the
    final position, memory growth (this process' RSS) and missed cycles. A repetition that
    fails (a fault: the controller refuses or aborts) is counted with its reason, and the
    faults are reset before the next one."""
    config = load_bus_config(settings.config_dir / f"{robot}.yaml")
    goal = tracking_goal(config)
    repetitions = []
    with running_stack(config, REAL_TIME) as stack:
        client = TrajectoryActionClient(stack.zenoh, config.robot.name)
        latest: list = [None]     # only the last joint state: the soak measures the stack
        subscriber = stack.zenoh.declare_subscriber(key(config.robot.name, "joint_states"),
                                              lambda sample: latest.__setitem__(0, sample))
        stack.node.statistics.clear()
        started = time.monotonic()
        rss_start = _rss_bytes()
        while time.monotonic() - started < seconds:
            try:
                result = client.wait_result(client.send_goal(goal), 60)
                outcome, reason = result.status.name.lower(), result.error_string
            except GoalRejected as exc:
                outcome, reason = "rejected", str(exc)
            if outcome != "succeeded":
                say(f"hil bench: soak repetition failed ({reason}); resetting faults")
                client.reset_faults()
            time.sleep(0.2)
            last = cdr.decode(latest[0].payload.to_bytes(), cdr.JOINT_STATE)
            final = dict(zip(last.name, last.position))
            error = max(abs(final[n] - p) for n, p in zip(goal.joint_names,
                                                          goal.points[-1].positions))
            repetitions.append({"t_s": time.monotonic() - started,
                                "result": outcome, "reason": reason,
                                "final_error": float(error), "rss_bytes": _rss_bytes(),
                                "missed_so_far": stack.node.statistics.missed})
            say(f"hil bench: soak {repetitions[-1]['t_s']:.0f} s: {outcome}"
                f", final error {error:.5f}, RSS {repetitions[-1]['rss_bytes'] / 1e6:.1f} MB")
        subscriber.undeclare()
        client.close()
        cycles = stack.node.statistics.count
    close_all()
    errors = [r["final_error"] for r in repetitions]
    return {"robot": robot, "seconds": seconds, "repetitions": len(repetitions),
            "failed": sum(r["result"] != "succeeded" for r in repetitions),
            "final_error_first": errors[0], "final_error_last": errors[-1],
            "final_error_max": max(errors), "rss_growth_bytes": _rss_bytes() - rss_start,
            # the first repetition warms up (first goal, first publications): growth after it
            # is what a long run would keep adding
            "rss_growth_after_first_bytes": (repetitions[-1]["rss_bytes"]
                                             - repetitions[0]["rss_bytes"]),
            "cycles": cycles, "missed": repetitions[-1]["missed_so_far"],
            "timeline": repetitions}


def _rss_bytes() -> int:
    with open("/proc/self/statm") as statm:
        return int(statm.read().split()[1]) * os.sysconf("SC_PAGE_SIZE")
