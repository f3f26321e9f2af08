"""hil across hosts: the drives' process and the controller's in two network namespaces the
test makes, joined by a veth pair it addresses and removes, over mutual TLS (--secure): a
trajectory runs; the link cut mid-trajectory stops the drives by their watchdogs and aborts
the goal naming them; the link back, a fault reset and a new goal succeed, nothing
restarted."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import time
import uuid

import pytest

from conftest import stop_process
from hil.zenoh_security import make_keys

#: judged against the host's stalls (tests/host_stalls.py): the processes run in real time
#: across network namespaces
pytestmark = [pytest.mark.slow, pytest.mark.real_time]

#: private addresses, used only inside the namespaces this test makes
DRIVES_HOST, CONTROLLER_HOST = "10.213.77.1", "10.213.77.2"
PORT = 7450


def namespaces_missing() -> str | None:
    if shutil.which("ip") is None:
        return "no `ip` command (iproute2) to make network namespaces"
    if os.geteuid() != 0:
        return "making network namespaces needs root"
    probe = f"hil-probe-{uuid.uuid4().hex[:6]}"
    made = subprocess.run(["ip", "netns", "add", probe], capture_output=True, text=True)
    if made.returncode != 0:
        return f"cannot make a network namespace here: {made.stderr.strip()}"
    subprocess.run(["ip", "netns", "del", probe], capture_output=True)
    return None


def ip(*args: str) -> None:
    subprocess.run(["ip", *args], check=True, capture_output=True, text=True)


class TwoHosts:
    """Namespaces ``drives`` and ``controller``, a veth pair between them (one end each),
    loopback up in both; every process started in them is stopped on close."""

    def __init__(self):
        tag = uuid.uuid4().hex[:6]
        self.drives, self.controller = f"hil-drv-{tag}", f"hil-ctl-{tag}"
        self.drives_link, self.controller_link = f"hd{tag}", f"hc{tag}"
        self.processes: list[subprocess.Popen] = []
        ip("netns", "add", self.drives)
        ip("netns", "add", self.controller)
        ip("link", "add", self.drives_link, "netns", self.drives, "type", "veth", "peer",
           "name", self.controller_link, "netns", self.controller)
        for namespace, link, address in ((self.drives, self.drives_link, DRIVES_HOST),
                                         (self.controller, self.controller_link,
                                          CONTROLLER_HOST)):
            ip("-n", namespace, "addr", "add", f"{address}/24", "dev", link)
            ip("-n", namespace, "link", "set", link, "up")
            ip("-n", namespace, "link", "set", "lo", "up")

    def start(self, namespace: str, *args: str) -> subprocess.Popen:
        process = subprocess.Popen(["ip", "netns", "exec", namespace, sys.executable, "-m",
                                    "hil", *args], stdout=subprocess.PIPE,
                                   stderr=subprocess.STDOUT, text=True)
        self.processes.append(process)
        return process

    def run(self, namespace: str, *args: str, timeout: float = 60) -> subprocess.CompletedProcess:
        return subprocess.run(["ip", "netns", "exec", namespace, sys.executable, "-m", "hil",
                               *args], capture_output=True, text=True, timeout=timeout)

    def link(self, up: bool) -> None:
        ip("-n", self.drives, "link", "set", self.drives_link, "up" if up else "down")

    def close(self) -> None:
        for process in reversed(self.processes):
            stop_process(process)
        for namespace in (self.drives, self.controller):    # the veth pair goes with them
            subprocess.run(["ip", "netns", "del", namespace], capture_output=True)


@pytest.fixture
def hosts():
    missing = namespaces_missing()
    if missing:
        pytest.skip(missing)
    made = TwoHosts()
    yield made
    made.close()


def test_a_cut_link_stops_the_drives_and_aborts_the_goal_and_a_reset_recovers(
        hosts, ur3_100hz, tmp_path):
    keys = tmp_path / "keys"
    make_keys(keys)
    secure = ("--secure", str(keys))
    sim = hosts.start(hosts.drives, "sim", ur3_100hz, *secure, "--status-period", "0",
                      "--listen", f"tcp/{DRIVES_HOST}:{PORT}")
    assert "hil sim:" in sim.stdout.readline()
    control = hosts.start(hosts.controller, "control", ur3_100hz, *secure,
                          "--connect", f"tcp/{DRIVES_HOST}:{PORT}",
                          "--listen", f"tcp/127.0.0.1:{PORT}")
    assert "hil control:" in control.stdout.readline()
    client = (*secure, "--connect", f"tcp/127.0.0.1:{PORT}")

    moved = hosts.run(hosts.controller, "send", "ur3", *client, "--joint", "joint2", "--to",
                      "0.3", "--in", "1s")
    assert moved.returncode == 0, moved.stdout + moved.stderr

    goal = subprocess.Popen(["ip", "netns", "exec", hosts.controller, sys.executable, "-m",
                             "hil", "send", "ur3", *client, "--joint", "joint2", "--to", "-0.3",
                             "--in", "4s"], stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                            text=True)
    hosts.processes.append(goal)
    time.sleep(1.5)
    hosts.link(up=False)
    time.sleep(2.0)
    hosts.link(up=True)
    aborted = goal.communicate(timeout=30)[0]
    assert goal.returncode != 0, aborted
    assert "silent" in aborted and "drive node" in aborted, aborted

    deadline = time.monotonic() + 30        # TCP retransmits: the link's frames resume
    while True:
        reset = hosts.run(hosts.controller, "reset", "ur3", *client)
        if reset.returncode == 0 or time.monotonic() > deadline:
            break
        time.sleep(1.0)
    assert reset.returncode == 0, reset.stdout + reset.stderr
    again = hosts.run(hosts.controller, "send", "ur3", *client, "--joint", "joint2", "--to",
                      "0.1", "--in", "1s")
    assert again.returncode == 0, again.stdout + again.stderr
    assert sim.poll() is None and control.poll() is None      # nothing restarted

    # the drives' own account: each stopped on its RPDO watchdog during the cut
    sim_output = stop_process(sim)
    for node in range(1, 7):
        assert f"node {node}: setpoints stopped arriving (RPDO timeout) (0x8250)" in sim_output
