"""What a careless or hostile peer cannot do to hil: garbage goals and frames, implausible
feedback, scripts that forget to close, and floods of frames into running processes."""

from __future__ import annotations

import itertools
import random
import signal
import struct
import subprocess
import sys
import textwrap
import threading
import time

import can
import canopen
import pytest

from hil.hardware import FaultKind

from conftest import EDS, ROOT, free_port

sys.path.insert(0, str(ROOT / "tools"))
import make_cia402_eds  # noqa: E402
import make_hipnuc_eds  # noqa: E402

#: judged against the host's stalls (tests/host_stalls.py): the stacks run in real time under
#: load
pytestmark = pytest.mark.real_time


@pytest.mark.parametrize("text, words", [
    ("points:\n  - {time_from_start: .nan, positions: [0.1]}", "time_from_start is nan"),
    ("goal_time_tolerance: .inf\npoints:\n  - {time_from_start: 1.0, positions: [0.1]}",
     "goal_time_tolerance is inf"),
    ("points:\n  - {time_from_start: 1e300, positions: [0.1]}", "time_from_start is 1e+300"),
    ("goal_tolerance: {joint1: .nan}\npoints:\n  - {time_from_start: 1.0, positions: [0.1]}",
     "goal_tolerance of joint 'joint1' is nan"),
], ids=["nan time", "inf goal time tolerance", "time beyond int32", "nan tolerance"])
def test_hil_send_names_what_a_trajectory_message_cannot_carry(tmp_path, text, words):
    trajectory = tmp_path / "goal.yaml"
    trajectory.write_text("joint_names: [joint1]\n" + text + "\n")
    result = subprocess.run(
        [sys.executable, "-m", "hil", "send", "ur3", str(trajectory), "--connect",
         f"tcp/127.0.0.1:{free_port()}"], capture_output=True, text=True, timeout=60)
    assert result.returncode == 1
    assert words in result.stderr and str(trajectory) in result.stderr
    assert "Traceback" not in result.stderr


def test_a_script_that_never_closes_its_action_client_still_exits(tmp_path):
    script = tmp_path / "client.py"
    script.write_text(textwrap.dedent(f"""
        from hil.messaging.zenoh_api import TrajectoryActionClient
        from hil.zenoh_session import ZenohSettings, session
        client = TrajectoryActionClient(
            session(ZenohSettings(connect=("tcp/127.0.0.1:{free_port()}",))), "ur3")
        client.wait_for_controller(0.1)
        print("done", flush=True)
    """))
    started = time.monotonic()
    result = subprocess.run([sys.executable, str(script)], capture_output=True, text=True,
                            timeout=50)       # it waited 60 s for its callback threads
    assert result.returncode == 0 and "done" in result.stdout, result.stderr
    print(f"exited {time.monotonic() - started:.1f} s after it started")


def test_feedback_no_joint_can_produce_is_a_fault_not_a_joint_state(controlled):
    """A TPDO the drive did not send (here from a third node on the bus) claims joint3 is far
    beyond its limits: the controller faults naming the drive and joint, and holds the last
    plausible position, never the injected one."""
    intruder = can.Bus(interface="virtual", channel=controlled.channel)
    try:
        counts = round(-789.8 * 120 / (2 * 3.141592653589793) * 131072)
        injected = can.Message(arbitration_id=0x183, is_extended_id=False,
                               data=struct.pack("<Hi", 0x0237, max(-2**31, counts)))
        # the drive's own TPDO follows each cycle: sent often enough, one lands last
        deadline = time.monotonic() + 5
        while not controlled.node.faults and time.monotonic() < deadline:
            intruder.send(injected)
            time.sleep(0.001)
    finally:
        intruder.shutdown()
    assert any((f.kind, f.node_id, f.joints) == (FaultKind.IMPLAUSIBLE, 3, ("joint3",))
               for f in controlled.node.faults), controlled.node.faults
    state = controlled.node.controller.state()
    assert abs(state.desired_positions[2]) < 3.2 and abs(state.actual_positions[2]) < 3.2


def test_the_shipped_eds_is_what_its_generator_writes():
    assert EDS.read_text() == make_cia402_eds.render(), \
        "bus_config/cia402_drive.eds was edited by hand: edit tools/make_cia402_eds.py and run it"
    assert make_hipnuc_eds.OUTPUT.read_text() == make_hipnuc_eds.render(), \
        "bus_config/hipnuc_imu.eds was edited by hand: edit tools/make_hipnuc_eds.py and run it"


# --- floods into running processes ------------------------------------------------------------

FLOOD_RATE = 10_000          # frames/s
FLOOD_SECONDS = 10.0


def _flood(channel: str, endpoint: str, kind: str, rate: float, seconds: float) -> int:
    """Send ``kind`` frames ("sdo": valid SDO reads of every node; "random": any id 0..0x7FF,
    any length 0..8) at up to ``rate`` for ``seconds``; returns how many were sent. The flood
    ends on time, not on count: Zenoh's congestion control blocks a put while the receiver
    is behind, so on a busy host fewer frames go out, never for longer."""
    bus = can.Bus(interface="zenoh", channel=channel, connect=[endpoint])
    rng = random.Random(17)
    sent, start = 0, time.monotonic()
    try:
        for i in itertools.count():
            if time.monotonic() - start >= seconds:
                break
            if kind == "sdo":
                msg = can.Message(arbitration_id=0x601 + i % 3, is_extended_id=False,
                                  data=bytes([0x40, 0x41, 0x60, 0, 0, 0, 0, 0]))
            else:
                msg = can.Message(arbitration_id=rng.randrange(0x800), is_extended_id=False,
                                  data=bytes(rng.randrange(256) for _ in range(rng.randrange(9))))
            bus.send(msg)
            sent += 1
            delay = start + (i + 1) / rate - time.monotonic()
            if delay > 0:
                time.sleep(delay)
    finally:
        bus.shutdown()
    return sent


def _probe_drive(channel: str, endpoint: str) -> int:
    """A fresh master on the bus: every node to PRE-OPERATIONAL (a random NMT frame may have
    stopped it), then node 1's device type over SDO."""
    bus = can.Bus(interface="zenoh", channel=channel, connect=[endpoint])
    network = canopen.Network(bus)
    network.notifier = can.Notifier(bus, network.listeners, 0.1)
    try:
        time.sleep(0.5)
        network.nmt.send_command(0x80)            # all nodes: enter PRE-OPERATIONAL
        node = canopen.RemoteNode(1, str(EDS))
        network.add_node(node)
        node.sdo.MAX_RETRIES, node.sdo.RESPONSE_TIMEOUT = 5, 1.0
        return node.sdo[0x1000].raw
    finally:
        network.notifier.stop(1)
        bus.shutdown()


@pytest.mark.slow
def test_a_flooded_real_time_stack_stays_up_answers_and_stops_on_sigterm(tmp_path):
    """10 s of valid SDO requests and 10 s of random frames, each at up to 10,000/s, into a
    real-time sim and its controller running a goal. Faults are expected (random NMT frames
    stop and reset drives); what must hold: both processes stay up and answer afterwards,
    stop on SIGTERM within 5 s, report what they dropped, and log no traceback."""
    sim_endpoint = f"tcp/127.0.0.1:{free_port()}"
    config = str(ROOT / "bus_config" / "ur3.yaml")
    logs = {name: (tmp_path / f"{name}.log").open("w+") for name in ("sim", "control")}
    processes = {}

    def start(name: str, *arguments: str) -> None:
        processes[name] = process = subprocess.Popen(
            [sys.executable, "-m", "hil", name, config, *arguments], stdout=logs[name],
            stderr=subprocess.STDOUT)
        deadline = time.monotonic() + 60
        while f"hil {name}: ur3" not in (tmp_path / f"{name}.log").read_text():
            assert process.poll() is None and time.monotonic() < deadline, \
                (tmp_path / f"{name}.log").read_text()
            time.sleep(0.2)

    try:
        start("sim", "--listen", sim_endpoint, "--status-period", "0")
        start("control", "--connect", sim_endpoint)
        time.sleep(2.0)
        goal = subprocess.Popen([sys.executable, "-m", "hil", "send", "ur3", "--joint", "joint1",
                                 "--to", "0.5", "--in", "15s", "--connect", sim_endpoint,
                                 "--quiet"], stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                                text=True)
        floods = {}
        for kind in ("sdo", "random"):
            flooder = threading.Thread(target=lambda k=kind: floods.__setitem__(k, _flood(
                "ur3/arm", sim_endpoint, k, FLOOD_RATE, FLOOD_SECONDS)))
            flooder.start()
            flooder.join(FLOOD_SECONDS * 3)
            assert not flooder.is_alive(), f"the {kind} flood could not be sent"
        print("flooded:", floods, "goal:", goal.communicate(timeout=60)[0].strip())
        # a tenth of the rate is still 50 times the drives' own traffic: a flood, not a trickle
        assert all(sent >= FLOOD_RATE * FLOOD_SECONDS / 10 for sent in floods.values()), floods
        for name, process in processes.items():
            assert process.poll() is None, f"hil {name} died in the flood"
        assert _probe_drive("ur3/arm", sim_endpoint) == 0x00020192     # the sim answers
        probe = subprocess.run([sys.executable, "-m", "hil", "reset", "ur3", "--connect",
                                sim_endpoint], capture_output=True, text=True, timeout=60)
        answer = probe.stdout + probe.stderr          # done, or failed with a reason
        assert "hil reset: done" in answer or "hil reset: failed" in answer, answer
        for name, process in processes.items():
            process.send_signal(signal.SIGTERM)
            started = time.monotonic()
            process.wait(timeout=30)
            stopped = time.monotonic() - started
            assert stopped < 5.0, f"hil {name} took {stopped:.1f} s to stop on SIGTERM"
    finally:
        for process in processes.values():
            if process.poll() is None:
                process.kill()
                process.wait()
    for name in processes:
        text = (tmp_path / f"{name}.log").read_text()
        print(f"--- hil {name}, last lines:\n" + "\n".join(text.splitlines()[-6:]))
        assert "Traceback" not in text, text[-4000:]
        assert f"hil {name}: bus arm: sent" in text, "no frame counts reported"
    assert "refused" in (tmp_path / "sim.log").read_text()
