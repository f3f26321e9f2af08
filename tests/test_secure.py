"""--secure: mutual TLS between hil's processes, and each role's rights enforced by the
process that would act (the drives' own process for CAN frames, the controller for goals)."""

from __future__ import annotations

import json
import subprocess
import sys
import time

import can
import pytest
import zenoh
from conftest import free_port, stop_process

from hil.controllers import TrajectoryGoal, TrajectoryPoint
from hil.errors import HilError
from hil.messaging import cdr
from hil.messaging.action import ACTION
from hil.messaging.controller_manager import ControllerManagerClient
from hil.messaging.zenoh_api import ControllerGone, TrajectoryActionClient, key
from hil.can.zenoh_receipts import declare_receipts, monitors_behind
from hil.zenoh_security import (
    COMMAND_KEYS,
    RECEIPT_KEYS,
    Identity,
    access_policy,
    make_keys,
    secured_endpoint,
)
from hil.zenoh_session import ZenohSettings, close, session, why_unreached

#: judged against the host's stalls (tests/host_stalls.py): the processes run in real time
pytestmark = [pytest.mark.slow, pytest.mark.real_time]

#: an SDO upload request of the device type (0x1000:00) to node 1, and its answer's id
SDO_REQUEST = can.Message(arbitration_id=0x601, data=bytes([0x40, 0x00, 0x10, 0, 0, 0, 0, 0]),
                          is_extended_id=False)
SDO_ANSWER = 0x581


@pytest.fixture(scope="module")
def keys(tmp_path_factory):
    folder = tmp_path_factory.mktemp("keys")
    make_keys(folder)
    return folder


@pytest.fixture(scope="module")
def other_keys(tmp_path_factory):
    folder = tmp_path_factory.mktemp("other-keys")
    make_keys(folder)
    return folder


def spawn(*args: str) -> subprocess.Popen:
    process = subprocess.Popen([sys.executable, "-m", "hil", *args], stdout=subprocess.PIPE,
                               stderr=subprocess.STDOUT, text=True)
    banner = process.stdout.readline()
    if not banner.startswith("hil "):
        process.kill()
        raise AssertionError(f"hil {args[0]} did not start: {banner}{process.stdout.read()}")
    return process


@pytest.fixture(scope="module")
def secure_sim(keys):
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    process = spawn("sim", "ur3", "--secure", str(keys), "--listen", endpoint,
                    "--status-period", "0")
    yield endpoint
    stop_process(process)


@pytest.fixture(scope="module")
def secure_controller(keys):
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    process = spawn("control", "ur3", "--fake", "--secure", str(keys), "--listen", endpoint)
    yield endpoint
    stop_process(process)


class Peer:
    """A session of ``role`` (keys of ``folder``) connected to ``endpoint``."""

    def __init__(self, folder, role: str, endpoint: str):
        self.settings = ZenohSettings(connect=(endpoint,), identity=Identity.of(folder, role))
        self.session = session(self.settings)

    def linked(self, timeout: float = 5.0) -> bool:
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            if list(self.session.info.peers_zid()):
                return True
            time.sleep(0.05)
        return False

    def sdo_answered(self) -> bool:
        """Whether node 1 answers an SDO request this peer puts on the arm bus."""
        bus = can.Bus(interface="zenoh", channel="ur3/arm", settings=self.settings)
        try:
            bus.send(SDO_REQUEST)
            deadline = time.monotonic() + 2.0
            while time.monotonic() < deadline:
                msg = bus.recv(0.1)
                if msg is not None and msg.arbitration_id == SDO_ANSWER:
                    return True
            return False
        finally:
            bus.shutdown()

    def close(self) -> None:
        close(self.settings)


@pytest.fixture
def peers():
    opened = []

    def peer(folder, role, endpoint) -> Peer:
        made = Peer(folder, role, endpoint)
        opened.append(made)
        return made

    yield peer
    for made in opened:
        made.close()


def test_the_drives_answer_the_controller_and_refuse_operators_and_observers(
        keys, secure_sim, peers):
    controller = peers(keys, "controller", secure_sim)
    assert controller.linked()
    assert controller.sdo_answered()
    for role in ("operator", "observer"):
        connected = peers(keys, role, secure_sim)
        assert connected.linked(), f"{role} did not connect"
        assert not connected.sdo_answered(), f"the drives acted on a frame of the {role}"


def test_a_certificate_of_another_ca_cannot_connect_and_is_told_why(
        other_keys, secure_sim, peers):
    stranger = peers(other_keys, "controller", secure_sim)
    assert not stranger.linked(timeout=3.0)
    assert "made no TLS session with this --secure process: a process without --secure, or " \
           "one with keys of another CA" in why_unreached(stranger.settings)


def test_a_process_without_tls_cannot_connect_and_is_told_to_give_secure(secure_sim):
    settings = ZenohSettings(connect=(secure_sim,))
    try:
        assert not list(session(settings).info.peers_zid())
        time.sleep(2.0)
        assert not list(session(settings).info.peers_zid())
        assert why_unreached(settings) == (
            f"something listens at {secure_sim} but made no Zenoh session with this plain-TCP "
            "process: a process with --secure takes TLS only (give --secure DIR here too)")
    finally:
        close(settings)


def test_a_process_dialling_a_port_nobody_listens_on_is_told_so_and_a_linked_one_nothing(
        secure_sim, keys, peers):
    nobody = f"tcp/127.0.0.1:{free_port()}"
    settings = ZenohSettings(connect=(nobody,))
    try:
        session(settings)
        assert why_unreached(settings) == f"nothing listens at {nobody}"
    finally:
        close(settings)
    controller = peers(keys, "controller", secure_sim)
    assert controller.linked() and why_unreached(controller.settings) is None


def _joint_states(peer: Peer) -> list:
    states = []
    peer.session.declare_subscriber(
        key("ur3", "joint_states"),
        lambda s: states.append(cdr.decode(s.payload.to_bytes(), cdr.JOINT_STATE)))
    return states


GOAL = TrajectoryGoal(("joint2",), (TrajectoryPoint(0.5, (0.3,), (0.0,)),))


def test_an_observer_sees_joint_states_but_cannot_send_goals_or_reset(
        keys, secure_controller, peers):
    observer = peers(keys, "observer", secure_controller)
    states = _joint_states(observer)
    client = TrajectoryActionClient(observer.session, "ur3")
    assert client.wait_for_controller(10)
    with pytest.raises(ControllerGone):           # the query never reached the server
        client.send_goal(GOAL, timeout=2.0)
    with pytest.raises(ControllerGone):
        client.reset_faults(timeout=2.0)
    time.sleep(1.0)
    assert states, "the observer receives no joint states"
    assert states[-1].position[list(states[-1].name).index("joint2")] == 0.0
    client.close()


def _an_operators_goal_succeeds(keys, endpoint, peers) -> None:
    operator = peers(keys, "operator", endpoint)
    client = TrajectoryActionClient(operator.session, "ur3")
    assert client.wait_for_controller(10)
    result = client.wait_result(client.send_goal(GOAL), timeout=10)
    assert result.error_code == 0
    client.close()


def test_an_operator_sends_goals(keys, secure_controller, peers):
    _an_operators_goal_succeeds(keys, secure_controller, peers)


def test_the_policy_denies_by_default_and_names_every_role():
    policy = access_policy()
    assert policy["default_permission"] == "deny"
    subjects = {s["id"]: s["cert_common_names"] for s in policy["subjects"]}
    assert subjects == {r: [r] for r in ("drives", "controller", "operator", "observer")}


def test_the_commands_the_controller_serves_are_the_ones_observers_may_not_query():
    served = [f"{key('ur3', ACTION)}/{name}" for name in ("send_goal", "cancel_goal",
                                                           "get_result")] + [
        key("ur3", "reset_faults")]
    denied = [zenoh.KeyExpr(k) for k in COMMAND_KEYS]
    assert [any(d.intersects(zenoh.KeyExpr(k)) for d in denied) for k in served] == [
        True, True, False, True]


def test_secure_endpoints_are_tls_and_refuse_other_protocols():
    assert secured_endpoint("tcp/10.0.0.1:7450") == "tls/10.0.0.1:7450"
    assert secured_endpoint("tls/10.0.0.1:7450") == "tls/10.0.0.1:7450"
    with pytest.raises(HilError, match="not TCP or TLS"):
        secured_endpoint("udp/10.0.0.1:7450")


def test_secure_without_keys_names_the_missing_files_and_the_command(tmp_path):
    with pytest.raises(HilError, match="hil keys init"):
        Identity.of(tmp_path, "drives")


def test_up_secure_runs_the_demo_and_records_it_each_process_in_its_role(keys, tmp_path):
    save = tmp_path / "run.rrd"
    result = subprocess.run([sys.executable, "-m", "hil", "up", "ur3", "--demo", "--lock-step",
                             "--secure", str(keys), "--no-viewer", "--save", str(save)],
                            capture_output=True, text=True, timeout=300, cwd=tmp_path)
    assert result.returncode == 0, result.stdout + result.stderr
    assert "demo succeeded" in result.stdout
    assert save.stat().st_size > 100_000       # the observer (hil viz) received the run


# --- side doors: wildcard and wider key expressions reach nothing a role may not touch ---
# (issue 43: an observer's query on `<goal key>$*` moved joint2 and reset faults; CAN frames
# put on `**` by an observer and on `hil/**` by an operator reached the drives)

GOAL_KEY = f"{key('ur3', ACTION)}/send_goal"
WIDER = ["**", "hil/**", "hil/ur3/*", "hil/ur3/**", f"{GOAL_KEY}$*",
         f"{key('ur3', 'reset_faults')}$*", "hil/*/**"]


def _goal_request() -> bytes:
    import uuid
    return cdr.encode(cdr.msg(cdr.SEND_GOAL_REQUEST, goal_id=cdr.uuid_msg(uuid.uuid4().hex),
                              goal=cdr.goal_msg(GOAL, 0.0)))


@pytest.mark.parametrize("role", ["observer", "operator"])
def test_no_wider_query_of_a_role_reaches_the_controllers_commands(
        keys, secure_controller, peers, role):
    peer = peers(keys, role, secure_controller)
    states = _joint_states(peer)
    assert TrajectoryActionClient(peer.session, "ur3").wait_for_controller(10)
    time.sleep(0.5)

    def joint2() -> float:
        assert states, "the peer receives no joint states"
        return states[-1].position[list(states[-1].name).index("joint2")]

    before = joint2()                  # where an earlier test's goal left it
    for expression in WIDER:
        replies = list(peer.session.get(expression, payload=_goal_request(), timeout=1.0))
        assert not replies, f"{role}'s query on {expression} was answered: {replies}"
    time.sleep(1.0)
    assert joint2() == before, "a goal reached the controller"


@pytest.mark.parametrize("role", ["observer", "operator"])
def test_no_frame_put_on_a_wider_key_reaches_the_drives(keys, secure_sim, peers, role):
    from hil.can.messages import frame_of
    from hil.can.zenoh_wire import decode_frames, encode_frames

    peer = peers(keys, role, secure_sim)
    assert peer.linked()
    answers: list = []

    def on_sample(sample) -> None:          # the drives' SDO answers (not the peer's own puts)
        for message in decode_frames(sample.payload.to_bytes()):
            answers.extend(f for f in message.frames if f.identifier == SDO_ANSWER)
    peer.session.declare_subscriber("hil/can/**", on_sample)
    message = encode_frames("ur3/arm", 12345, 1, time.time(), [frame_of(SDO_REQUEST)])
    for expression in ("**", "hil/**", "hil/can/**", "hil/can/ur3/*", "hil/can/ur3/arm",
                       "hil/can/ur3/arm$*"):
        peer.session.put(expression, message)
    time.sleep(2.0)
    assert not answers, f"the drives answered a frame the {role} put"


def test_the_operator_and_observer_may_not_serve_or_publish(keys, secure_controller, peers):
    """A role that may not answer queries cannot pose as the controller: its queryable on a
    command key is never asked, its replies and puts are not taken."""
    impostor = peers(keys, "observer", secure_controller)
    asked = []
    impostor.session.declare_queryable(GOAL_KEY, lambda query: asked.append(query))
    _an_operators_goal_succeeds(keys, secure_controller, peers)
    assert not asked, "the operator's goal went to an observer posing as the controller"


def test_no_process_sends_a_query_to_an_operator_or_observer(keys):
    """Zenoh sends a query to a peer linked a moment ago before its declarations are known,
    so the querier's own egress rule keeps command queries from reaching a client: shown here
    with an operator that (against hil's policy) believed an observer's queryable, asking it
    with every target; none reaches it."""
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    credulous = access_policy()
    credulous["policies"].append({"rules": ["anything"], "subjects": ["observer"]})
    operator_config = ZenohSettings(listen=(endpoint,),
                                    identity=Identity.of(keys, "operator")).to_config()
    operator_config.insert_json5("access_control", json.dumps(credulous))
    operator = zenoh.open(operator_config)
    observer = Peer(keys, "observer", endpoint)
    try:
        assert observer.linked()
        asked = []
        observer.session.declare_queryable(GOAL_KEY, asked.append)
        time.sleep(1.0)                     # its declaration has reached the operator
        for target in (zenoh.QueryTarget.BEST_MATCHING, zenoh.QueryTarget.ALL):
            for _ in range(5):
                list(operator.get(GOAL_KEY, target=target, timeout=1.0))
        assert not asked, "an operator's goal query went to an observer"
    finally:
        observer.close()
        operator.close()


def test_the_policy_gives_operators_and_observers_allow_lists_only():
    policy = access_policy()
    rules = {r["id"]: r for r in policy["rules"]}
    assert all(r["permission"] == "allow" for r in rules.values())
    granted = {role: [name for p in policy["policies"] if role in p["subjects"]
                      for name in p["rules"]] for role in ("operator", "observer")}
    for role, names in granted.items():
        ingress = [rules[n] for n in names if "ingress" in rules[n]["flows"]]
        keys_of = {k for r in ingress for k in r["key_exprs"]}
        assert "**" not in keys_of, f"{role} may do anything somewhere"
        assert not any("put" in r["messages"] for r in ingress), f"{role} may publish"
        egress = [rules[n] for n in names if "egress" in rules[n]["flows"]]
        asked = [r for r in egress if "query" in r["messages"]]
        # the one query a client is sent: its CAN log's receipts (an observer's)
        assert egress and all(r["key_exprs"] == RECEIPT_KEYS for r in asked), \
            f"a process may send the {role} a query"
        served = [r for r in ingress if "declare_queryable" in r["messages"]]
        assert all(r["key_exprs"] == RECEIPT_KEYS for r in served), f"{role} may serve"


def test_a_lock_step_sender_asks_an_observer_its_receipts_and_nothing_else(keys, peers):
    """An observer's log answers which frames it heard (hil.can.zenoh_receipts), so that a
    lock-step sender closes only once its last frame is logged: the sender asks and gets the
    answer through the policy, and the receipts' query is all an observer is asked, by any
    queryable it declares (a wider one sees that query, a command key's nothing)."""
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    sender = ZenohSettings(listen=(endpoint,), identity=Identity.of(keys, "controller"))
    asking = session(sender)
    observer = peers(keys, "observer", endpoint)
    try:
        assert observer.linked()
        wide, goals = [], []
        receipts = declare_receipts(observer.session, lambda: [("ur3/arm", {7: 3})])
        observer.session.declare_queryable("hil/**", lambda q: wide.append(str(q.key_expr)))
        observer.session.declare_queryable(GOAL_KEY, goals.append)
        deadline = time.monotonic() + 10
        while monitors_behind(asking, "ur3/arm", 7, 5) != 1:
            assert time.monotonic() < deadline, "the observer's receipts never came"
            time.sleep(0.05)
        for expression in (GOAL_KEY, "hil/**", "hil/ur3/**"):
            list(asking.get(expression, timeout=1.0))
        assert not goals and wide and set(wide) == {"hil/can-receipts/*"}, (wide, goals)
        receipts.undeclare()
    finally:
        close(sender)


def test_a_stall_report_counts_only_from_the_benchs_own_roles(keys, peers):
    """hil up blames the bench (exit 3) or a drive (exit 1) on its stall count: a stall put
    by an operator or an observer, on the stall key or a wider one, is not counted; one of
    the drives' process is (issue 43)."""
    from hil.messaging.zenoh_api import StallPublisher, StallSubscriber
    from hil.realtime.stalls import Stall

    endpoint = f"tcp/127.0.0.1:{free_port()}"
    listening = ZenohSettings(listen=(endpoint,), identity=Identity.of(keys, "operator"))
    counted: list = []
    subscriber = StallSubscriber(session(listening), "ur3", counted.append,
                                 lambda error: counted.append(error))
    try:
        payload = cdr.encode(cdr.msg(cdr.STALL, process="sim", at=time.time(), length=0.5,
                                     steal=0.0, where=""))
        for role in ("operator", "observer"):
            peer = peers(keys, role, endpoint)
            assert peer.linked()
            for expression in (key("ur3", "stalls"), "hil/ur3/*", "hil/**", "**"):
                peer.session.put(expression, payload)
        time.sleep(1.0)
        assert not counted, "a stall from a role outside the bench was counted"
        drives = peers(keys, "drives", endpoint)
        assert drives.linked()
        publisher = StallPublisher(drives.session, "ur3")
        try:
            publisher.publish(Stall("sim", time.time(), 0.5, 0.0))
            deadline = time.monotonic() + 5.0
            while not counted and time.monotonic() < deadline:
                time.sleep(0.05)
        finally:
            publisher.close()
        assert [stall.process for stall in counted] == ["sim"]
    finally:
        subscriber.close()
        close(listening)


def test_an_observer_lists_controllers_but_cannot_switch_or_command_them(
        keys, secure_controller, peers):
    """The controller manager's list is a read; its switch and a forward controller's
    commands are an operator's commands (an observer's queries are not answered)."""
    observer = ControllerManagerClient(peers(keys, "observer", secure_controller).session,
                                       "ur3", timeout=2.0)
    operator = ControllerManagerClient(peers(keys, "operator", secure_controller).session,
                                       "ur3", timeout=10.0)
    assert {s.name for s in operator.list()} >= {"joint_trajectory_controller"}
    assert {s.name for s in observer.list()} >= {"joint_trajectory_controller"}
    with pytest.raises(TimeoutError):
        observer.switch(["forward_position_controller"], ["joint_trajectory_controller"])
    with pytest.raises(TimeoutError):
        observer.command("forward_position_controller", [0.0] * 6, wait=True)
    assert operator.switch(["forward_position_controller"], ["joint_trajectory_controller"]) == (
        True, "Successfully switched controllers!")
    operator.command("forward_position_controller", [0.0] * 6, wait=True)
    assert operator.switch(["joint_trajectory_controller"], ["forward_position_controller"]) == (
        True, "Successfully switched controllers!")
