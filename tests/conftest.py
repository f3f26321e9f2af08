"""Shared fixtures: the seed robots, the bad-input corpus, a package path."""

from __future__ import annotations

import collections
import queue
import signal
import socket
import subprocess
import sys
import threading
import time
from collections.abc import Callable
from pathlib import Path

import can
import canopen
import hypothesis
import numpy as np
import pytest
import yaml

from hil import protocols
from hil.bus_config import load_bus_config
from hil.can import socketcan_missing as can_socketcan_missing
from hil.cli import main
from hil.controllers import TrajectoryGoal, TrajectoryPoint
from hil.description import PackagePath, load_description
from hil.messaging import cdr
from hil.messaging.zenoh_api import ProcessWatch, TrajectoryActionClient
from hil.stack import Stack
from hil.testing import DrivesBench
from hil.zenoh_session import (
    MEETING_VARIABLE, ZenohSettings, close, free_loopback_port, session,
)

TESTS = Path(__file__).resolve().parent
ROOT = TESTS.parent
UR3_XACRO = ROOT / "robots" / "ur3_description" / "urdf" / "ur3.xacro"
PIGOT_XACRO = ROOT / "robots" / "pigot_description" / "urdf" / "pigot.xacro"
CORPUS = TESTS / "corpus"
COUPLED_URDF = TESTS / "fixtures" / "coupled_transmissions.urdf"

#: a test judged against the host's stalls (tests/host_stalls.py)
pytest_plugins = ["host_stalls", "process_leaks"]

# hypothesis' default 200 ms deadline per example is a wall-clock assert: a host that pauses
# a vCPU for 0.3 s fails it on a pure function (CI, 2026-11-28); a test that does mean a
# deadline sets it in its own settings
hypothesis.settings.register_profile("hil", deadline=None)
hypothesis.settings.load_profile("hil")


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    """Over SocketCAN only the tests marked ``wire`` run (see _socketcan_cases); then the
    files whose tests are allowed longest (their ``timeout`` marks) first, the rest in their
    order: under ``--dist loadfile`` each file goes to the next idle worker in this order
    (pyproject's ``--no-loadscope-reorder``), and the long SocketCAN file handed out last ran
    alone at the end of the run (2026-11-29). A stable sort: each file's tests stay together
    and in order."""
    _socketcan_cases(config, items)

    def allowed(item: pytest.Item) -> float:
        mark = item.get_closest_marker("timeout")
        return float(mark.args[0]) if mark is not None and mark.args else 0.0
    longest: dict[Path, float] = {}
    for item in items:
        longest[item.path] = max(longest.get(item.path, 0.0), allowed(item))
    items.sort(key=lambda item: -longest[item.path])


def _socketcan_cases(config: pytest.Config, items: list[pytest.Item]) -> None:
    """Deselect the SocketCAN variants (the ``transport`` fixture's) of the tests not marked
    ``wire``. The virtual bus checks what a drive answers, case by case; SocketCAN adds the
    wire (the kernel's delivery to other sockets, RTR frames, bursts, a drive's timers
    against real frames), which the ``wire`` tests check, at about 20 s a test inside
    User-Mode Linux: all 64 took 20-30 minutes there beside a second worker on a 2-vCPU
    host like CI's (2026-11-29)."""
    dropped = [item for item in items
               if getattr(item, "callspec", None) is not None     # only parametrised ones
               and item.callspec.params.get("transport") == "socketcan"
               and item.get_closest_marker("wire") is None]
    if dropped:
        config.hook.pytest_deselected(items=dropped)
        items[:] = [item for item in items if item not in dropped]


def judged_in_real_time(request: pytest.FixtureRequest) -> None:
    """Mark the test that uses a real-time fixture ``real_time``: its failure while the host
    stalled past its margins is inconclusive (tests/host_stalls.py)."""
    request.node.add_marker(pytest.mark.real_time)


class FrameRecorder(can.Listener):
    """A bus listener keeping each frame with the thread that delivered it."""

    def __init__(self):
        self.frames: list[tuple[can.Message, int]] = []
        self._arrived = threading.Condition()

    def on_message_received(self, msg: can.Message) -> None:
        with self._arrived:
            self.frames.append((msg, threading.get_ident()))
            self._arrived.notify_all()

    def wait_for(self, count: int, timeout: float) -> bool:
        """Whether ``count`` frames are in within ``timeout`` seconds."""
        with self._arrived:
            return self._arrived.wait_for(lambda: len(self.frames) >= count, timeout)

    def wait_for_message(self, match: Callable[[can.Message], bool], timeout: float) -> bool:
        """Whether a frame that ``match`` accepts is in within ``timeout`` seconds."""
        with self._arrived:
            return self._arrived.wait_for(
                lambda: any(match(msg) for msg, _ in self.frames), timeout)


#: a device family from outside hil, 29-bit CAN FD frames only: its package and .dist-info
#: side by side, as pip leaves an installed one (test_toy_protocol.py)
TOY = TESTS / "fixtures" / "toy_protocol"


@pytest.fixture
def toy_installed(monkeypatch):
    """The toy family installed for this test only: its folder on sys.path (where
    importlib.metadata finds the .dist-info's entry point), hil's registry read afresh, and
    forgotten afterwards."""
    monkeypatch.syspath_prepend(str(TOY))
    protocols._registered.cache_clear()
    protocols.protocol.cache_clear()
    yield
    protocols._registered.cache_clear()
    protocols.protocol.cache_clear()
    for name in [name for name in sys.modules if name.startswith("hil_toy_protocol")]:
        del sys.modules[name]


@pytest.fixture(scope="session")
def package_path() -> PackagePath:
    """The corpus folder first, then robots/ (no environment influence)."""
    return PackagePath((CORPUS, ROOT / "robots"))


@pytest.fixture(scope="session")
def ur3(package_path):
    return load_description(UR3_XACRO, package_path)


@pytest.fixture(scope="session")
def pigot(package_path):
    return load_description(PIGOT_XACRO, package_path)


@pytest.fixture(scope="session")
def coupled(package_path):
    return load_description(COUPLED_URDF, package_path)


# --- CAN benches -------------------------------------------------------------

UR3_VIRTUAL = TESTS / "fixtures" / "ur3_virtual.yaml"
EDS = ROOT / "bus_config" / "cia402_drive.eds"
#: DriveParameters fields for the 1e-3 kg m^2 test motor: velocity loop ~200 rad/s,
#: position loop 40/s
TEST_MOTOR_DRIVE = dict(counts_per_rev=4096, rated_torque=1.0, peak_torque=2.0,
                        position_kp=40.0, velocity_kp=0.2, velocity_ki=10.0,
                        max_velocity=100.0, following_error_limit=0.5,
                        following_error_timeout=0.005, quick_stop_deceleration=500.0,
                        watchdog_timeout=0.1, position_limits=(-50.0, 50.0))


free_port = free_loopback_port


@pytest.fixture
def endpoint():
    return f"tcp/127.0.0.1:{free_port()}"


@pytest.fixture
def bus_pair(endpoint):
    """Two buses on one channel, in two Zenoh sessions joined over loopback."""
    channel = f"test/{time.monotonic_ns()}"
    a = can.Bus(interface="zenoh", channel=channel, listen=[endpoint])
    b = can.Bus(interface="zenoh", channel=channel, connect=[endpoint])  # linked to a
    yield a, b
    a.shutdown()
    b.shutdown()


@pytest.fixture(autouse=True)
def meeting_point_of_its_own(monkeypatch):
    """Every test's hil processes meet at a loopback port of the test's own (the child
    processes inherit $HIL_ZENOH_ENDPOINT), not at 7450, which a user's bench or a process
    another test left behind may hold."""
    monkeypatch.setenv(MEETING_VARIABLE, f"tcp/127.0.0.1:{free_port()}")


def socketcan_missing(*channels: str) -> str | None:
    """None if the SocketCAN channels (vcan0 unless named) can be opened, else why not."""
    missing = can_socketcan_missing(channels or ("vcan0",))
    return missing and (f"{missing}; tools/uml_run.py runs these tests inside User-Mode Linux "
                        "(test_socketcan_in_uml.py)")


@pytest.fixture(params=["virtual", pytest.param("socketcan", marks=pytest.mark.socketcan)])
def transport(request) -> str | None:
    """The SocketCAN interface of a bench's drives (vcan0), or None: python-can virtual."""
    if request.param == "socketcan":
        missing = socketcan_missing()
        if missing:
            pytest.skip(missing)
        return "vcan0"
    return None


#: how much longer than canopen's defaults (SDO answer 0.3 s, 402 state change 0.4 s, all
#: of them 0.8 s) the tests' canopen master waits. These tests pin what the drive answers,
#: not how fast: inside User-Mode Linux on a loaded 2-CPU host the guest kernel alone
#: stalls the drive's thread for longer than canopen's defaults (the CI run of 2026-11-24:
#: 15 of the 59 SocketCAN tests timed out in canopen's master, none in hil)
MASTER_PATIENCE = 5.0


def patient(node):
    """``node`` (a canopen RemoteNode or BaseNode402) with MASTER_PATIENCE x its timeouts."""
    node.sdo.RESPONSE_TIMEOUT = canopen.sdo.client.SdoClient.RESPONSE_TIMEOUT * MASTER_PATIENCE
    for name in ("TIMEOUT_SWITCH_STATE_SINGLE", "TIMEOUT_SWITCH_STATE_FINAL",
                 "TIMEOUT_SWITCH_OP_MODE", "TIMEOUT_RESET_FAULT", "TIMEOUT_CHECK_TPDO"):
        if hasattr(node, name):
            setattr(node, name, getattr(node, name) * MASTER_PATIENCE)
    return node


class CanopenBench:
    """python canopen's master on a DrivesBench of a config (the ur3 fixture's): a Network on
    the master's bus of its bus "arm", SYNC produced on demand, CiA 402 nodes of hil's EDS.
    Real time unless ``lock_step``; on SocketCAN interface ``vcan`` where given."""

    def __init__(self, config: Path = UR3_VIRTUAL, vcan: str | None = None,
                 lock_step: bool = False):
        self.drives = DrivesBench(config, lock_step=lock_step,
                                  vcan=None if vcan is None else {"arm": vcan})
        self.config, self.sim = self.drives.config, self.drives.sim
        #: the master's bus: python-can's, beside the drives' (a fresh master joins with
        #: ``can.Bus(interface=bench.interface, channel=bench.channel)``)
        self.interface, self.channel = self.drives.interface, self.drives.channel("arm")
        self.master_bus = self.drives.bus("arm")
        self.network = canopen.Network(self.master_bus)
        self.network.notifier = can.Notifier(self.master_bus, self.network.listeners, 0.1)
        self._sync_running = False

    def stop_sync(self) -> None:
        """Stop the SYNC producer (idempotent: a second BCM delete fails on SocketCAN)."""
        if self._sync_running:
            self.network.sync.stop()
            self._sync_running = False

    def start_sync(self, period: float) -> None:
        self.network.sync.start(period)
        self._sync_running = True

    def node402(self, node_id: int) -> canopen.BaseNode402:
        node = patient(canopen.BaseNode402(node_id, str(EDS)))
        self.network.add_node(node)
        return node

    def close(self) -> None:
        self.stop_sync()
        for node in self.network.values():
            node.rpdo.stop()
        self.network.notifier.stop(1)
        self.drives.close()


@pytest.fixture
def canopen_bench(transport, request):
    """A CanopenBench of the ur3 fixture, real time, on the test's transport."""
    judged_in_real_time(request)
    made = CanopenBench(vcan=transport)
    yield made
    made.close()


class RealTimeMaster:
    """A master's python-can bus on a real-time DrivesBench of a one-drive config, for a
    client library's test: :meth:`ask` sends a frame and takes the drive's answer; the joint
    and the simulated drive (for what its protocol does not report) at hand. ``channel``:
    where a client library opens its own bus (python-can ``virtual``, or the bench's vcan)."""

    def __init__(self, bench: DrivesBench):
        self.bench = bench
        self.interface = bench.interface
        self.channel = bench.channel(bench.config.buses[0].name)
        self.bus = bench.bus()
        #: the simulated drive
        self.drive = bench.sim.drives[0]
        self._joint = bench.config.buses[0].drives[0].joints[0]

    @classmethod
    def of(cls, config: Path, vcan: str | None = None) -> RealTimeMaster:
        """A master of a new bench of ``config`` (its drives on SocketCAN interface ``vcan``
        where given), closed with :meth:`close`."""
        loaded = load_bus_config(config)
        return cls(DrivesBench(loaded, vcan=None if vcan is None else
                               {loaded.buses[0].name: vcan}))

    def ask(self, can_id: int, data: bytes = b"", timeout: float = 2.0, remote: bool = False,
            answer_id: int | None = None) -> can.Message | None:
        """Send a frame; the next frame the drives send (on ``answer_id`` if given)."""
        while self.bus.recv(0) is not None:
            pass
        self.bus.send(can.Message(arbitration_id=can_id, data=data, is_extended_id=False,
                                  is_remote_frame=remote))
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            reply = self.bus.recv(max(0.0, deadline - time.monotonic()))
            if reply is not None and (answer_id is None or reply.arbitration_id == answer_id):
                return reply
        return None

    def joint(self) -> float:
        """The position of the drive's (first) joint, now."""
        return self.bench.joint(self._joint)

    def close(self) -> None:
        self.bench.close()


def hils_master_moves(config_path: Path, joint: str, target: float):
    """hil's own master (a lock-step stack of the config) moves ``joint`` to ``target`` in
    one second: (the goal's result, where the plant's first joint ends)."""
    from hil.realtime import LOCK_STEP
    from hil.stack import running_stack

    config = load_bus_config(config_path)
    with running_stack(config, LOCK_STEP) as stack:
        client = TrajectoryActionClient(stack.zenoh, config.robot.name)
        goal = TrajectoryGoal((joint,), (TrajectoryPoint(1.0, (target,), (0.0,)),))
        result = client.wait_result(client.send_goal(goal), timeout=60)
        client.close()
        return result, float(stack.sim.plant.joint_positions()[0])


# --- an in-process controller stack --------------------------------------------

class ControlledBench(Stack):
    """The ur3 fixture as a hil.stack.Stack on a python-can virtual bus, the sim's end able
    to lose, delay and corrupt frames (``sim_bus.add``); an action client on the node's own
    Zenoh session (loopback)."""

    def __init__(self):
        super().__init__(load_bus_config(UR3_VIRTUAL), interface="virtual", injectable=True)
        self.channel = self.channels["arm"]
        self.sim_bus = self.sim_buses["arm"]
        self.hardware = self.node.hardware
        self.client = TrajectoryActionClient(self.zenoh, "ur3")
        assert self.client.wait_for_controller(30), "the control node did not come up"

    def fault(self, node_id: int) -> None:
        self.sim.raise_fault("arm", node_id)         # sends the EMCY, as a real drive would
        deadline = time.monotonic() + 5
        while not self.node.faults and time.monotonic() < deadline:
            time.sleep(0.01)
        assert self.node.faults, "the controller did not notice the fault"

    def move(self, joint: str, to: float, seconds: float = 0.5) -> str:
        return self.client.send_goal(TrajectoryGoal((joint,), (
            TrajectoryPoint(seconds, (to,), (0.0,)),)))

    def close(self) -> None:
        self.client.close()
        super().close()


@pytest.fixture
def controlled(request):
    judged_in_real_time(request)
    bench = ControlledBench()
    yield bench
    bench.close()


# --- processes -------------------------------------------------------------------


def ur3_at_100hz(folder: Path) -> Path:
    """bus_config/ur3.yaml with its buses at 100 Hz, written into ``folder``. For real time
    across processes on a shared 2-CPU machine: at 500 Hz the master rightly calls a drive
    silent after 5 missed answers (8 ms), and a busy neighbour stalls a process that long now
    and then; at 100 Hz that takes 40 ms, so tests that pin something else are not flaky."""
    return shipped_at_100hz("ur3", folder)


def shipped_at_100hz(name: str, folder: Path) -> Path:
    """bus_config/<name>.yaml with its buses at 100 Hz, written into ``folder`` (see
    :func:`ur3_at_100hz`)."""
    config = yaml.safe_load((ROOT / "bus_config" / f"{name}.yaml").read_text())
    config["robot"] = str((ROOT / "bus_config" / config["robot"]).resolve())
    for bus in config["buses"]:
        bus["cycle_hz"] = 100
    path = folder / f"{name}_100hz.yaml"
    path.write_text(yaml.safe_dump(config))
    return path


@pytest.fixture
def ur3_100hz(tmp_path, request) -> str:
    """The path of :func:`ur3_at_100hz`'s config, in the test's folder (for a real-time run:
    the test is judged so)."""
    judged_in_real_time(request)
    return str(ur3_at_100hz(tmp_path))


def stop_process(process: subprocess.Popen, timeout: float = 20) -> str:
    """Ctrl-C to a `hil` process started with text stdout, then its output (killed if it
    does not end within ``timeout``)."""
    if process.poll() is None:
        process.send_signal(signal.SIGINT)
    try:
        return process.communicate(timeout=timeout)[0] or ""
    except subprocess.TimeoutExpired:
        process.kill()
        return process.communicate()[0] or ""


class DelayingRelay:
    """A TCP relay on loopback that holds every byte ``delay`` seconds each way: a slow link
    (the kernel here has no netem). Listens on ``port`` (given, or a free one), forwards to
    ``target`` (a port on 127.0.0.1); ``close`` ends it and its connections."""

    def __init__(self, target: int, delay: float, port: int = 0):
        self.target, self.delay = target, delay
        self._server = socket.create_server(("127.0.0.1", port))
        self.port = self._server.getsockname()[1]
        self._sockets: list[socket.socket] = [self._server]
        self._closed = threading.Event()
        threading.Thread(target=self._accept, daemon=True).start()

    def _accept(self) -> None:
        while not self._closed.is_set():
            try:
                client, _ = self._server.accept()
                upstream = socket.create_connection(("127.0.0.1", self.target))
            except OSError:
                return
            self._sockets += [client, upstream]
            for source, sink in ((client, upstream), (upstream, client)):
                held: queue.Queue = queue.Queue()
                threading.Thread(target=self._read, args=(source, held), daemon=True).start()
                threading.Thread(target=self._write, args=(held, sink), daemon=True).start()

    def _read(self, source: socket.socket, held: queue.Queue) -> None:
        try:
            while data := source.recv(65536):
                held.put((time.monotonic() + self.delay, data))
        except OSError:
            pass
        held.put((0.0, b""))

    def _write(self, held: queue.Queue, sink: socket.socket) -> None:
        while True:
            due, data = held.get()
            if not data:
                break
            time.sleep(max(0.0, due - time.monotonic()))
            try:
                sink.sendall(data)
            except OSError:
                break
        try:
            sink.shutdown(socket.SHUT_WR)
        except OSError:
            pass

    def close(self) -> None:
        self._closed.set()
        for each in self._sockets:
            each.close()


def read_rrd(path, whole: bool = True):
    """Rows per entity (temporal) and the static entity paths of an .rrd file: ``whole``
    (closed: read through rerun's manifest, which a file without one fails), or scanned up
    to where it was cut off, as rerun's viewer scans a file without one."""
    import rerun.chunk      # noqa: PLC0415 (only the recording tests need rerun)

    rows, static = collections.Counter(), set()
    reader = rerun.chunk.RrdReader(path)
    for chunk in (reader.store() if whole else reader).stream():
        if chunk.is_static:
            static.add(chunk.entity_path)
        else:
            rows[chunk.entity_path] += chunk.num_rows
    return rows, static


def rrd_verify_errors(path) -> str:
    """What rerun's own verifier (``rerun rrd verify``: every column against rerun's
    schema) says is wrong with an .rrd file; empty when it passes."""
    rerun_cli = Path(sys.executable).with_name("rerun")
    result = subprocess.run([str(rerun_cli), "rrd", "verify", str(path)], capture_output=True,
                            text=True, timeout=120)
    return "" if result.returncode == 0 else (result.stdout + result.stderr)[-2000:]


def rrd_series(path, entity: str) -> tuple[np.ndarray, np.ndarray]:
    """An entity's scalar series in an .rrd file: its sim times (s) and its values (one row
    per time, a column per series), in time order; rows logged before the sim was heard (on
    the wall's timeline only) left out."""
    import rerun.chunk      # noqa: PLC0415 (only the recording tests need rerun)

    times, values = [], []
    for chunk in rerun.chunk.RrdReader(path).store().stream():
        if chunk.entity_path != entity or chunk.is_static:
            continue
        batch = chunk.to_record_batch()
        if "sim_time" not in batch.schema.names:
            continue
        times += [t / 1e9 for t in batch.column("sim_time").cast("int64").to_pylist()]
        values += batch.column("Scalars:scalars").to_pylist()
    order = np.argsort(times)
    return np.asarray(times)[order], np.asarray(values, dtype=float)[order]


def example_robot_data() -> Path | None:
    """Where the test extra's example-robot-data keeps its share folder (robots under
    ``example-robot-data/robots``), or None where it is not installed."""
    from importlib.metadata import PackageNotFoundError, distribution  # noqa: PLC0415

    try:
        found = Path(distribution("example-robot-data").locate_file("cmeel.prefix/share"))
    except PackageNotFoundError:
        return None
    return found if (found / "example-robot-data" / "robots").is_dir() else None


def init_check_and_demo(description: Path, folder: Path, share: Path,
                        protocol: str | None = None) -> tuple[Path, Path]:
    """The README's "Adding a robot" commands, unedited, on a public description: ``hil init``
    (of ``protocol``'s drives, if given), ``hil check``, then ``hil up --demo`` in lock-step
    recording (CI's two shared CPUs are no place to judge real time; ``hil bench`` is),
    which must succeed. The config's and the recording's paths."""
    config = folder / "robot.yaml"
    found = ["--package-path", str(share)]
    drives = ["--protocol", protocol] if protocol else []
    assert main(["init", str(description), "-o", str(config), *drives, *found]) == 0
    assert main(["check", str(config), *found]) == 0
    save = folder / "robot.rrd"
    up = subprocess.run([sys.executable, "-m", "hil", "up", str(config), "--demo", "--lock-step",
                         "--no-viewer", "--save", str(save), *found],
                        capture_output=True, text=True, timeout=560, cwd=folder)
    assert up.returncode == 0, up.stdout[-3000:] + up.stderr[-3000:]
    assert "hil up: demo succeeded" in up.stdout
    return config, save


@pytest.fixture
def processes():
    """Processes a test starts; every one is ended (and reaped) afterwards."""
    started: list[subprocess.Popen] = []
    yield started
    for process in started:
        if process.poll() is None:
            process.kill()
        process.communicate()


def linked(settings: ZenohSettings, robot: str, process: str, timeout: float = 60) -> bool:
    """Whether ``robot``'s ``process`` (``sim``, ``control/held``, ...) is seen within
    ``timeout`` through the session of ``settings`` (a test's bus): Zenoh peers relay
    nothing, so its token seen there says that session and the process are linked directly,
    and a frame either sends from now on reaches the other. A bus' open waits for the peers
    on its channel that its linked peers report (hil.can.zenoh_links); where the session
    they meet at has no bus (a test's bare watch), none reports the others, and a process
    that opens its bus after the test's is linked to it in gossip's own time."""
    watch = ProcessWatch(session(settings), robot)
    try:
        return watch.wait_alive(process, timeout)
    finally:
        watch.close()


@pytest.fixture
def watched_robot():
    """A Zenoh session listening on a loopback port, watching the ur3's processes: (the
    endpoint to give a process, its ProcessWatch)."""
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    settings = ZenohSettings(listen=(endpoint,))
    watch = ProcessWatch(session(settings), "ur3")
    yield endpoint, watch
    watch.close()
    close(settings)


def imu_messages(config, count: int) -> list:
    """The first ``count`` sensor_msgs/Imu samples the controller of a hil.stack.Stack of
    ``config`` publishes of its IMU named 'imu' (the stack closed after)."""
    return sensor_messages(config, "imu", "imu", cdr.IMU, count)


def sensor_messages(config, name: str, kind: str, typename: str, count: int) -> list:
    """The first ``count`` samples (of ROS type ``typename``) the controller of a
    hil.stack.Stack of ``config`` publishes of its sensor ``name`` on
    hil/<robot>/sensors/<name>/<kind> (the stack closed after)."""
    stack = Stack(config)
    arrived: queue.SimpleQueue = queue.SimpleQueue()
    subscriber = stack.zenoh.declare_subscriber(
        f"hil/{config.robot.name}/sensors/{name}/{kind}",
        lambda sample: arrived.put(sample.payload.to_bytes()))
    try:
        return [cdr.decode(arrived.get(timeout=30), typename) for _ in range(count)]
    finally:
        subscriber.undeclare()
        stack.close()


def wait_until(condition, timeout: float = 10.0) -> None:
    """Return once ``condition()`` holds (polled every 10 ms); fail after ``timeout`` s."""
    pause = threading.Event()
    for _ in range(int(timeout / 0.01)):
        if condition():
            return
        pause.wait(0.01)
    raise AssertionError(f"the condition did not come in {timeout:g} s")


def sensor_frames_a_second(path: Path) -> float:
    """The frames a second the sensors of the bus config at ``path`` add to its first bus'
    load (the config's load less that of a copy without them, written beside it)."""
    config = yaml.safe_load(path.read_text())
    del config["sensors"]
    bare = path.with_name(f"{path.stem}_bare.yaml")
    bare.write_text(yaml.safe_dump(config))
    return (load_bus_config(path).buses[0].load().frames_per_second
            - load_bus_config(bare).buses[0].load().frames_per_second)


class RecordingRouter:
    """What a sensor needs of its bus' router (hil.can.router.FrameRouter): the handlers it
    subscribed, by identifier, and the frames it sent, in order."""

    def __init__(self):
        self.handlers: dict[int, Callable] = {}
        self.sent: list = []

    def subscribe(self, identifier: int, handler: Callable) -> None:
        self.handlers[identifier] = handler

    def unsubscribe(self, identifier: int, handler: Callable) -> None:
        del self.handlers[identifier]

    def send(self, frame) -> None:
        self.sent.append(frame)

    def send_frames(self, frames) -> None:
        self.sent.extend(frames)
