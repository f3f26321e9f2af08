"""hil's processes on one host find each other with no endpoints given, in any order."""

from __future__ import annotations

import os
import re
import subprocess
import sys
import time
from pathlib import Path

import pytest

from conftest import DelayingRelay, free_port, stop_process
from hil.zenoh_session import MEETING_VARIABLE

#: judged against the host's stalls (tests/host_stalls.py): the processes meet and run in real
#: time
pytestmark = [pytest.mark.slow, pytest.mark.real_time]


class Processes:
    """hil commands run with defaults only, meeting at a loopback port of their own
    ($HIL_ZENOH_ENDPOINT: the test's port, not 7450, which a user's bench may hold)."""

    def __init__(self):
        self.env = {**os.environ, MEETING_VARIABLE: f"tcp/127.0.0.1:{free_port()}"}
        self.started: list[subprocess.Popen] = []

    def start(self, *args: str, cwd: Path | None = None) -> subprocess.Popen:
        process = subprocess.Popen([sys.executable, "-m", "hil", *args], env=self.env, cwd=cwd,
                                   stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
        self.started.append(process)
        return process

    def run(self, *args: str, timeout: float = 60) -> subprocess.CompletedProcess:
        return subprocess.run([sys.executable, "-m", "hil", *args], env=self.env,
                              capture_output=True, text=True, timeout=timeout)

    def stop(self) -> list[str]:
        """SIGINT to every process started, in reverse order; their outputs."""
        return [stop_process(process) for process in reversed(self.started)]


@pytest.fixture
def processes():
    made = Processes()
    yield made
    made.stop()


def test_fake_controller_and_send_meet_with_no_endpoints(processes):
    control = processes.start("control", "ur3", "--fake")
    assert "hil control:" in control.stdout.readline()
    sent = processes.run("send", "ur3", "--joint", "joint2", "--to", "0.3", "--in", "1s")
    assert sent.returncode == 0, sent.stdout + sent.stderr
    assert "succeeded" in sent.stdout


def _wait_for_line(process: subprocess.Popen, start: str, limit: int = 200) -> list[str]:
    """The lines ``process`` printed up to the first that starts with ``start``."""
    lines = []
    while len(lines) < limit:
        line = process.stdout.readline()
        assert line, "".join(lines)
        lines.append(line)
        if line.startswith(start):
            return lines
    raise AssertionError("".join(lines))


@pytest.mark.parametrize("client", [
    ("send", "ur3", "--joint", "joint2", "--to", "0.3", "--in", "1s"),
    ("reset", "ur3"),
    ("ls",),
])
def test_hil_up_and_a_client_meet_with_no_endpoints(processes, tmp_path, client):
    """`hil up ur3` in one terminal, a client in another, both with their defaults (issue
    46: hil up listened on a random port, the clients dialled the meeting point).
    Lock-step: whether they meet is the point, not timing on a loaded host."""
    up = processes.start("up", "ur3", "--lock-step", "--no-viewer", cwd=tmp_path)
    _wait_for_line(up, "  [")            # the run's progress: every process is up
    done = processes.run(*client)
    assert done.returncode == 0, done.stdout + done.stderr
    if client == ("ls",):
        assert re.search(r"ur3\n(\s+(sim|control|viz) .*\n){3}", done.stdout), done.stdout


def test_hil_up_and_a_second_viewer_meet_with_no_endpoints(processes, tmp_path):
    up = processes.start("up", "ur3", "--lock-step", "--no-viewer", cwd=tmp_path)
    _wait_for_line(up, "  [")
    viz = processes.start("viz", "ur3", "--lock-step", "--save", str(tmp_path / "second.rrd"),
                          "--status-period", "1")
    lines = _wait_for_line(viz, "hil viz:")
    time.sleep(3.0)
    assert viz.poll() is None, "".join(lines)
    outputs = processes.stop()
    assert (tmp_path / "second.rrd").stat().st_size > 0, outputs[0]


def test_ls_with_nothing_running_says_so_and_what_to_do(processes):
    done = processes.run("ls", "--timeout", "0.5")
    assert done.returncode == 1
    assert "no hil process is reachable" in done.stderr and "Traceback" not in done.stderr


def test_viewer_sim_and_controller_started_in_that_order_meet(processes, ur3_100hz, tmp_path):
    viz = processes.start("viz", ur3_100hz, "--save", str(tmp_path / "run.rrd"))
    sim = processes.start("sim", ur3_100hz, "--status-period", "0")
    assert "hil sim:" in sim.stdout.readline()
    control = processes.start("control", ur3_100hz)
    assert "hil control:" in control.stdout.readline()
    sent = processes.run("send", "ur3", "--joint", "joint2", "--to", "0.3", "--in", "1s")
    assert sent.returncode == 0, sent.stdout + sent.stderr
    assert viz.poll() is None


def test_controller_started_before_its_sim_waits_for_the_drives(processes, ur3_100hz, tmp_path):
    control = processes.start("control", ur3_100hz)
    assert "hil control:" in control.stdout.readline()
    time.sleep(2.0)       # the drives' boot-up is not there yet: the controller waits
    assert control.poll() is None
    sim = processes.start("sim", ur3_100hz, "--status-period", "0")
    assert "hil sim:" in sim.stdout.readline()
    viz = processes.start("viz", ur3_100hz, "--save", str(tmp_path / "run.rrd"))
    sent = processes.run("send", "ur3", "--joint", "joint2", "--to", "0.3", "--in", "1s")
    assert sent.returncode == 0, sent.stdout + sent.stderr
    assert viz.poll() is None
    outputs = processes.stop()
    assert "drives disabled" in outputs[-1]            # the controller's, stopped last


def test_controller_gives_up_on_drives_that_never_boot_naming_them(processes, ur3_100hz):
    control = processes.run("control", ur3_100hz, "--boot-timeout", "2")
    assert control.returncode != 0
    assert "drive node 1 (joint1) on bus 'arm'" in control.stderr
    assert "not heard within 2 s" in control.stderr
    assert "Traceback" not in control.stderr


def test_a_second_sim_or_controller_of_one_robot_is_refused_naming_it(processes, ur3_100hz):
    sim = processes.start("sim", ur3_100hz, "--status-period", "0")
    assert "hil sim:" in sim.stdout.readline()
    control = processes.start("control", ur3_100hz, "--fake")
    assert "hil control:" in control.stdout.readline()
    for process in ("sim", "control"):
        second = processes.run(process, ur3_100hz, *(["--fake"] if process == "control" else []))
        assert second.returncode == 1
        assert f"a hil {process} for robot 'ur3' already runs" in second.stderr
        assert "Traceback" not in second.stderr


def test_a_slow_link_to_the_drives_is_named_as_the_link_not_the_drives(processes):
    """20 ms each way between controller and drives (a relay that holds every byte: this
    kernel has no netem) against a 2 ms cycle: the drives' answers cannot come in their
    cycle, and the controller says the link is slow, with its measured round trip: the
    bench's, not the drives' (exit status 3, the link's slow round trips named in a line)."""
    sim_port = free_port()
    sim = processes.start("sim", "ur3", "--listen", f"tcp/127.0.0.1:{sim_port}")
    assert "hil sim:" in sim.stdout.readline()
    relay = DelayingRelay(sim_port, 0.02)
    try:
        control = processes.run("control", "ur3", "--connect",
                                f"tcp/127.0.0.1:{relay.port}", timeout=120)
    finally:
        relay.close()
    said = control.stdout + control.stderr
    assert control.returncode == 3, said
    assert re.search(r"the bench itself stalled during the bring-up: the link was slow \d+ "
                     r"times, round trips from [\d:.]+, up to \d+ ms \(ur3/(arm|wrist)", said)
    named = re.search(r"the link of bus 'arm' takes ([\d.]+) ms a round trip, over the "
                      r"[\d.]+ ms the answers have: a slow link \(the network, or a Zenoh end "
                      r"falling behind\), not the drives", said)
    assert named and 40.0 <= float(named.group(1)) < 200.0, said
