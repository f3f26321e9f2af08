"""hil's controller as a ROS 2 node on rmw_zenoh, seen by a client written from the
specification alone (tests/ros_spec_client.py) through a Zenoh router with rmw_zenohd's
settings, everything on loopback: the ur3 in lock-step, in this process."""

from __future__ import annotations

import ast
import os
import queue
import subprocess
import sys
import threading
import time
import uuid
from pathlib import Path

import pytest
import zenoh
import zenoh.ext

from conftest import ROOT
from ros_spec_client import ATTACHMENT, SpecClient
from hil.bus_config import load_bus_config
from hil.bus_config.locate import config_path
from hil.controllers import TrajectoryGoal, TrajectoryPoint
from hil.messaging import cdr
from hil.messaging.ros.face import (
    ACTION_NAME, PlantClock, RosClockFace, RosControlFace, RosSettings,
)
from hil.messaging.zenoh_api import SimClockPublisher
from hil.messaging.ros.router import open_router
from hil.stack import running_stack
from hil.zenoh_session import ZenohSettings, close, free_loopback_port, session
from hil.realtime import LOCK_STEP

JOINT_STATE_JAZZY = "RIHS01_a13ee3a330e346c9d87b5aa18d24e11690752bd33a0350f11c5882bc9179260e"
ACTION = f"/{ACTION_NAME}/_action"
UR3_JOINTS = [f"joint{i}" for i in range(1, 7)]
SUCCEEDED, CANCELED, ABORTED, EXECUTING = 4, 5, 6, 2


@pytest.fixture(scope="module")
def router():
    endpoint = f"tcp/127.0.0.1:{free_loopback_port()}"
    session = open_router((endpoint,))
    yield endpoint
    session.close()


def _stack(router, namespace: str = "/"):
    settings = RosSettings(router=router, namespace=namespace)
    return running_stack(
        load_bus_config(config_path("ur3")), LOCK_STEP,
        faces=[lambda node: RosControlFace(settings, node.controller, node.clock,
                                           "<robot name='ur3'/>", node.reset_faults,
                                           manager=node.manager)])


@pytest.fixture(scope="module")
def stack(router):
    with _stack(router) as running:
        yield running


@pytest.fixture
def client(router, stack):
    spec = SpecClient(router)
    yield spec
    spec.close()


def test_the_spec_client_uses_nothing_of_hils_ros_adapter():
    tree = ast.parse((ROOT / "tests" / "ros_spec_client.py").read_text())
    imported = {a.name for n in ast.walk(tree) if isinstance(n, ast.Import) for a in n.names}
    imported |= {n.module for n in ast.walk(tree) if isinstance(n, ast.ImportFrom)}
    assert not any(name.startswith("hil.messaging.ros") for name in imported), imported


def test_the_graph_shows_the_node_and_every_endpoint(client):
    tokens = client.graph()
    assert any(t.kind == "NN" and t.node == "hil_control" for t in tokens)
    states = client.find("MP", "/joint_states")
    assert (states.type_name, states.type_hash) == ("sensor_msgs::msg::dds_::JointState_",
                                                    JOINT_STATE_JAZZY)
    for service in ("send_goal", "cancel_goal", "get_result"):
        assert client.find("SS", f"{ACTION}/{service}").node == "hil_control"
    assert client.find("MP", f"{ACTION}/feedback").qos == "::,10:,:,:,,"
    assert client.find("MP", f"{ACTION}/status").qos == ":1:,1:,:,:,,"   # transient local
    assert client.find("MP", "/robot_description").qos == ":1:,1:,:,:,,"
    assert client.find("MP", "/diagnostics").type_name == (
        "diagnostic_msgs::msg::dds_::DiagnosticArray_")
    assert client.find("SS", "/hil_control/reset_faults").type_name == (
        "std_srvs::srv::dds_::Trigger_")


def test_joint_states_arrive_with_the_attachment_in_sequence(client):
    samples: queue.Queue = queue.Queue()
    subscriber = client.session.declare_subscriber(
        client.find("MP", "/joint_states").key(0),
        lambda s: samples.put((s.payload.to_bytes(), s.attachment.to_bytes())))
    try:
        received = [samples.get(timeout=10) for _ in range(5)]
    finally:
        subscriber.undeclare()
    attachments = [ATTACHMENT.unpack(a) for _, a in received]
    sequence = [a[0] for a in attachments]
    # one number per sample sent: increasing (a sample dropped on a congested link skips one)
    assert all(later > earlier for earlier, later in zip(sequence, sequence[1:])), sequence
    assert len({a[3] for a in attachments}) == 1 and all(a[2] == 16 for a in attachments)
    message = cdr.decode(received[-1][0], cdr.JOINT_STATE)
    assert list(message.name) == UR3_JOINTS and len(message.position) == 6


def test_robot_description_reaches_a_late_subscriber(client):
    token = client.find("MP", "/robot_description")
    texts: queue.Queue = queue.Queue()
    subscriber = zenoh.ext.declare_advanced_subscriber(
        client.session, token.key(0), lambda s: texts.put(s.payload.to_bytes()),
        history=zenoh.ext.HistoryConfig(detect_late_publishers=True))
    try:
        text = cdr.TYPES.deserialize_cdr(texts.get(timeout=10), "std_msgs/msg/String").data
    finally:
        subscriber.undeclare()
    assert text == "<robot name='ur3'/>"


def _goal_request(goal_id: str, seconds: float, joint3: float) -> bytes:
    goal = TrajectoryGoal(("joint3",), (TrajectoryPoint(seconds, (joint3,), (0.0,)),))
    return cdr.encode(cdr.msg(cdr.SEND_GOAL_REQUEST, goal_id=cdr.uuid_msg(goal_id),
                              goal=cdr.goal_msg(goal)))


def _send(client: SpecClient, request: bytes, action: str = ACTION) -> bool:
    reply = client.call(client.find("SS", f"{action}/send_goal"), request)
    return cdr.decode(reply, cdr.SEND_GOAL_RESPONSE).accepted


def _result(client: SpecClient, goal_id: str, action: str = ACTION):
    reply = client.call(client.find("SS", f"{action}/get_result"), cdr.encode(cdr.msg(
        cdr.GET_RESULT_REQUEST, goal_id=cdr.uuid_msg(goal_id))))
    return cdr.decode(reply, cdr.GET_RESULT_RESPONSE)


def _collect(client: SpecClient, name: str, typename: str):
    """A subscriber that decodes into a list, and the list."""
    got: list = []
    subscriber = client.session.declare_subscriber(
        client.find("MP", name).key(0),
        lambda s: got.append(cdr.decode(s.payload.to_bytes(), typename)))
    return subscriber, got


def test_a_goal_runs_to_its_result_with_feedback_and_status(client):
    feedback_sub, feedback = _collect(client, f"{ACTION}/feedback", cdr.FEEDBACK_MESSAGE)
    status_sub, statuses = _collect(client, f"{ACTION}/status",
                                    "action_msgs/msg/GoalStatusArray")
    goal_id = uuid.uuid4().hex
    try:
        assert _send(client, _goal_request(goal_id, 1.0, 0.4))
        response = _result(client, goal_id)          # answered when the goal ends
        time.sleep(0.2)
    finally:
        feedback_sub.undeclare()
        status_sub.undeclare()
    assert response.status == SUCCEEDED and response.result.error_code == 0
    assert any(cdr.goal_id_of(f.goal_id) == goal_id for f in feedback)
    ours = [s.status for array in statuses for s in array.status_list
            if cdr.goal_id_of(s.goal_info.goal_id) == goal_id]
    assert ours and set(ours) <= {EXECUTING, SUCCEEDED} and ours[-1] == SUCCEEDED, ours


def test_a_second_goal_is_canceled(client):
    first, second = uuid.uuid4().hex, uuid.uuid4().hex
    assert _send(client, _goal_request(first, 0.5, 0.1))
    assert _result(client, first).status == SUCCEEDED
    assert _send(client, _goal_request(second, 30.0, 0.8))
    info = cdr.msg("action_msgs/msg/GoalInfo", goal_id=cdr.uuid_msg(second),
                   stamp=cdr.time_msg(0.0))
    reply = cdr.decode(client.call(client.find("SS", f"{ACTION}/cancel_goal"), cdr.encode(
        cdr.msg(cdr.CANCEL_REQUEST, goal_info=info))), cdr.CANCEL_RESPONSE)
    assert reply.return_code == 0
    assert [cdr.goal_id_of(g.goal_id) for g in reply.goals_canceling] == [second]
    assert _result(client, second).status == CANCELED


def test_a_goal_for_no_known_goal_id_has_status_unknown(client):
    assert _result(client, uuid.uuid4().hex).status == 0


def test_refused_and_malformed_goals_are_answered_not_accepted_and_reported(client):
    diagnostics_sub, diagnostics = _collect(client, "/diagnostics", cdr.DIAGNOSTIC_ARRAY)
    try:
        goal = TrajectoryGoal(("no_such_joint",), (TrajectoryPoint(1.0, (0.1,)),))
        assert not _send(client, cdr.encode(cdr.msg(
            cdr.SEND_GOAL_REQUEST, goal_id=cdr.uuid_msg(uuid.uuid4().hex),
            goal=cdr.goal_msg(goal))))
        assert not _send(client, b"\x00\x01\x00\x00garbage")
        time.sleep(0.3)
    finally:
        diagnostics_sub.undeclare()
    messages = [s.message for array in diagnostics for s in array.status]
    assert any("no_such_joint" in m for m in messages), messages
    assert any("malformed" in m for m in messages), messages


def test_a_request_without_the_attachment_gets_an_error_reply(client):
    token = client.find("SS", f"{ACTION}/get_result")
    replies = list(client.session.get(token.key(0), payload=cdr.EMPTY_REQUEST, timeout=5))
    assert replies and replies[0].err is not None
    assert b"attachment" in replies[0].err.payload.to_bytes()


def test_the_fault_reset_service_answers(client):
    reply = client.call(client.find("SS", "/hil_control/reset_faults"), cdr.EMPTY_REQUEST)
    response = cdr.decode(reply, cdr.TRIGGER_RESPONSE)
    assert response.success and response.message == "no fault to reset"


def test_a_result_awaited_at_shutdown_is_answered_aborted(router):
    with _stack(router, "/second") as running:     # beside the module's stack, as a 2nd robot
        spec = SpecClient(router)
        action = f"/second{ACTION}"
        try:
            goal_id = uuid.uuid4().hex
            assert _send(spec, _goal_request(goal_id, 30.0, 0.8), action)
            answers: queue.Queue = queue.Queue()
            waiter = threading.Thread(target=lambda: answers.put(_result(spec, goal_id,
                                                                          action)))
            waiter.start()
            time.sleep(0.5)
            running.node.stop()
            response = answers.get(timeout=20)
            waiter.join()
        finally:
            spec.close()
    assert response.status == ABORTED
    assert "shutting down" in response.result.error_string


def test_clock_carries_the_given_plant_time(router):
    face = RosClockFace(RosSettings(router=router))
    spec = SpecClient(router)
    try:
        token = spec.find("MP", "/clock")
        assert token.type_name == "rosgraph_msgs::msg::dds_::Clock_"
        clocks: queue.Queue = queue.Queue()
        subscriber = spec.session.declare_subscriber(
            token.key(0), lambda s: clocks.put(s.payload.to_bytes()))
        time.sleep(0.2)
        face.publish(12.25)
        clock = cdr.TYPES.deserialize_cdr(clocks.get(timeout=5), "rosgraph_msgs/msg/Clock").clock
        subscriber.undeclare()
    finally:
        spec.close()
        face.close()
    assert (clock.sec, clock.nanosec) == (12, 250_000_000)


def _hil(*args: str, timeout: float = 60) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "hil", *args], cwd=ROOT, capture_output=True,
                          text=True, timeout=timeout)


def test_hil_send_and_reset_with_ros_drive_the_face(router, stack):
    sent = _hil("send", "--ros", f"--ros-router={router}", "--joint", "joint2", "--to", "0.2",
                "--in", "0.5s", "--quiet")
    assert sent.returncode == 0, sent.stdout + sent.stderr
    assert "succeeded" in sent.stdout
    reset = _hil("reset", "--ros", f"--ros-router={router}")
    assert reset.returncode == 0 and "no fault to reset" in reset.stdout, reset.stderr


def test_ros_options_without_a_router_fail_with_what_to_do():
    nowhere = f"tcp/127.0.0.1:{free_loopback_port()}"
    result = _hil("control", "ur3", "--fake", "--ros", f"--ros-router={nowhere}")
    assert result.returncode != 0
    assert "cannot reach the Zenoh router" in result.stderr and "hil router" in result.stderr
    assert "Traceback" not in result.stderr
    bad = _hil("send", "--ros", "--ros-domain-id=999", "--joint", "j", "--to", "0")
    assert bad.returncode != 0 and "outside 0..232" in bad.stderr


def test_hil_sim_with_ros_publishes_the_plants_time_on_clock(router):
    sim = subprocess.Popen(
        [sys.executable, "-m", "hil", "sim", "ur3", "--duration", "20", "--status-period", "0",
         f"--listen=tcp/127.0.0.1:{free_loopback_port()}", "--ros", f"--ros-router={router}"],
        cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    spec = SpecClient(router)
    try:
        token = spec.find("MP", "/clock", timeout=30)
        assert token.node == "hil_sim"
        scheduling = _zenoh_threads_scheduling(sim.pid)
        clocks: queue.Queue = queue.Queue()
        subscriber = spec.session.declare_subscriber(
            token.key(0), lambda s: clocks.put(s.payload.to_bytes()))
        times = []
        for _ in range(20):
            clock = cdr.TYPES.deserialize_cdr(clocks.get(timeout=10),
                                              "rosgraph_msgs/msg/Clock").clock
            times.append(clock.sec + clock.nanosec * 1e-9)
        subscriber.undeclare()
    finally:
        spec.close()
        sim.terminate()
        output = sim.communicate(timeout=30)[0]
    assert times == sorted(times) and times[-1] > times[0], times
    assert sim.returncode == 0 and "all drives disabled" in output, output
    # the ROS session shares Zenoh's runtime threads with the frames' session: they keep the
    # sim's scheduling and CPUs (the ROS session opened first once left them to the normal
    # scheduler, on any CPU)
    main, threads = scheduling
    assert threads and all(setting == main for setting in threads.values()), (main, threads)


def _zenoh_threads_scheduling(pid: int):
    """(policy, CPUs) of a process' main thread, and of each of its Zenoh runtime threads."""
    def setting(tid: int):
        stat = (Path(f"/proc/{pid}/task/{tid}/stat").read_text().rsplit(")", 1)[1].split())
        return int(stat[38]), frozenset(os.sched_getaffinity(tid))   # field 41: policy
    threads = {}
    for task in Path(f"/proc/{pid}/task").iterdir():
        name = (task / "comm").read_text().strip()
        if name.split("-")[0] in ("net", "rx", "tx", "app"):
            threads[f"{name}/{task.name}"] = setting(int(task.name))
    return setting(pid), threads


def test_the_plant_clock_tells_no_time_before_its_first_sample():
    """A message stamped before the plant's time was known and re-stamped after (late, on a
    stalled host) gets no plant time: extrapolated back it would read before the clock's
    first sample (CI, 2026-11-29: a joint state at 99.9 s after a clock starting at 100)."""
    settings = ZenohSettings(listen=(f"tcp/127.0.0.1:{free_loopback_port()}",))
    clock = PlantClock(session(settings), "ur3")
    try:
        assert clock.at(1000.0) is None
        clock.add(1000.0, 100.0)
        clock.add(1000.05, 100.1)                      # twice the wall's pace
        assert clock.at(999.99) is None
        assert clock.at(1000.0) == pytest.approx(100.0)
        assert clock.at(1000.1) == pytest.approx(100.2)
    finally:
        clock.close()
        close(settings)


def test_use_sim_time_stamps_joint_states_feedback_and_goals_on_the_plants_clock(router):
    hil_session = ZenohSettings(listen=(f"tcp/127.0.0.1:{free_loopback_port()}",))
    plant = PlantClock(session(hil_session), "ur3")
    sim_clock = SimClockPublisher(session(hil_session), "ur3")
    settings = RosSettings(router=router, namespace="/simtime")
    spec = SpecClient(router)
    try:
        with running_stack(load_bus_config(config_path("ur3")), LOCK_STEP,
                           faces=[lambda node: RosControlFace(
                               settings, node.controller, node.clock, "<robot/>",
                               plant_clock=plant)]):
            states_sub, states = _collect(spec, "/simtime/joint_states", cdr.JOINT_STATE)
            feedback_sub, feedback = _collect(spec, f"/simtime{ACTION}/feedback",
                                              cdr.FEEDBACK_MESSAGE)
            status_sub, statuses = _collect(spec, f"/simtime{ACTION}/status",
                                            "action_msgs/msg/GoalStatusArray")
            time.sleep(0.3)
            assert not states, "joint states published before the plant's time was known"
            now = time.time()
            sim_clock.publish(now - 0.05, 100.0)       # the plant runs at twice the wall's pace
            sim_clock.publish(now, 100.1)
            goal_id = uuid.uuid4().hex
            reply = spec.call(spec.find("SS", f"/simtime{ACTION}/send_goal"),
                              _goal_request(goal_id, 1.0, 0.3))
            accepted = cdr.decode(reply, cdr.SEND_GOAL_RESPONSE)
            assert accepted.accepted
            assert _result(spec, goal_id, f"/simtime{ACTION}").status == SUCCEEDED
            states_sub.undeclare()
            feedback_sub.undeclare()
            status_sub.undeclare()
    finally:
        spec.close()
        sim_clock.close()
        close(hil_session)
    stamps = [cdr.seconds_of(m.header.stamp) for m in states]
    assert stamps and all(100.0 < t < 200.0 for t in stamps), stamps[:5]
    assert feedback and all(100.0 < cdr.seconds_of(f.feedback.header.stamp) < 200.0
                            for f in feedback)
    # rcl_action stamps goals on the node's ROS time: the plant's here
    assert 100.0 < cdr.seconds_of(accepted.stamp) < 200.0
    goal_stamps = [cdr.seconds_of(s.goal_info.stamp) for array in statuses
                   for s in array.status_list if cdr.goal_id_of(s.goal_info.goal_id) == goal_id]
    assert goal_stamps and all(100.0 < t < 200.0 for t in goal_stamps), goal_stamps


#: control_msgs 6.3's FollowJointTrajectory feedback (ROS 2 Kilted, Lyrical), from its .action
KILTED_FEEDBACK = """std_msgs/Header header
string[] joint_names
trajectory_msgs/JointTrajectoryPoint desired
trajectory_msgs/JointTrajectoryPoint actual
trajectory_msgs/JointTrajectoryPoint error
int32 index
string[] multi_dof_joint_names
trajectory_msgs/MultiDOFJointTrajectoryPoint multi_dof_desired
trajectory_msgs/MultiDOFJointTrajectoryPoint multi_dof_actual
trajectory_msgs/MultiDOFJointTrajectoryPoint multi_dof_error
int32 multi_dof_index"""
#: what ROS computes for it (the prefix reported on issue 27, checked against ROS's own
#: hash computation over control_msgs 6.3's definitions)
KILTED_FEEDBACK_MESSAGE_HASH = "RIHS01_95618cc7"


def test_a_kilted_client_receives_feedback_in_control_msgs_6s_layout_with_point_indices(router):
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore
    kilted = get_typestore(Stores.ROS2_KILTED)
    kilted.register(get_types_from_msg(KILTED_FEEDBACK,
                                       "control_msgs/action/FollowJointTrajectory_Feedback"))
    kilted.register(get_types_from_msg(
        "unique_identifier_msgs/UUID goal_id\n"
        "control_msgs/action/FollowJointTrajectory_Feedback feedback", cdr.FEEDBACK_MESSAGE))
    settings = RosSettings(router=router, namespace="/kilted", distro="kilted")
    spec = SpecClient(router)
    action = f"/kilted{ACTION}"
    got: list = []
    try:
        with running_stack(load_bus_config(config_path("ur3")), LOCK_STEP,
                           faces=[lambda node: RosControlFace(
                               settings, node.controller, node.clock, "<robot/>")]):
            token = spec.find("MP", f"{action}/feedback")
            assert token.type_hash.startswith(KILTED_FEEDBACK_MESSAGE_HASH), token.type_hash
            subscriber = spec.session.declare_subscriber(
                token.key(0), lambda s: got.append(kilted.deserialize_cdr(
                    s.payload.to_bytes(), cdr.FEEDBACK_MESSAGE)))
            goal_id = uuid.uuid4().hex
            goal = TrajectoryGoal(("joint3",), tuple(
                TrajectoryPoint(t, (q,), (0.0,)) for t, q in ((0.5, 0.1), (1.0, 0.2),
                                                              (1.5, 0.3))))
            request = cdr.encode(cdr.msg(cdr.SEND_GOAL_REQUEST, goal_id=cdr.uuid_msg(goal_id),
                                         goal=cdr.goal_msg(goal)))
            assert _send(spec, request, action)
            assert _result(spec, goal_id, action).status == SUCCEEDED
            time.sleep(0.2)
            subscriber.undeclare()
    finally:
        spec.close()
    ours = [f.feedback for f in got if cdr.goal_id_of(f.goal_id) == goal_id]
    assert ours, "no feedback decoded in Kilted's layout"
    indices = [f.index for f in ours]
    assert indices == sorted(indices) and {0, 1, 2} <= set(indices), indices
    assert all(f.multi_dof_index == 0 and list(f.joint_names) == UR3_JOINTS for f in ours)


# --- the node's standard services, from rcl_interfaces' and type_description_interfaces'
# .srv definitions alone (a codec of the test's own) --------------------------------------

SERVICE_PARTS = {
    "spec/msg/ListRequest": "string[] prefixes\nuint64 depth",
    "spec/msg/ListResponse": "rcl_interfaces/msg/ListParametersResult result",
    "spec/msg/GetRequest": "string[] names",
    "spec/msg/GetResponse": "rcl_interfaces/msg/ParameterValue[] values",
    "spec/msg/DescribeRequest": "string[] names",
    "spec/msg/DescribeResponse": "rcl_interfaces/msg/ParameterDescriptor[] descriptors",
    "spec/msg/SetRequest": "rcl_interfaces/msg/Parameter[] parameters",
    "spec/msg/SetResponse": "rcl_interfaces/msg/SetParametersResult[] results",
    "spec/msg/TypeRequest": "string type_name\nstring type_hash\nbool include_type_sources",
    "spec/msg/TypeResponse":
        "bool successful\nstring failure_reason\n"
        "type_description_interfaces/msg/TypeDescription type_description\n"
        "type_description_interfaces/msg/TypeSource[] type_sources\n"
        "type_description_interfaces/msg/KeyValue[] extra_information",
}
DOUBLE, STRING, STRING_ARRAY = 3, 4, 9


@pytest.fixture(scope="module")
def spec_types():
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore
    store = get_typestore(Stores.ROS2_JAZZY)
    for name, text in SERVICE_PARTS.items():
        store.register(get_types_from_msg(text, name))
    return store


def _ask(client, types, service: str, request_type: str, response_type: str, **fields):
    request = types.types[f"spec/msg/{request_type}"](**fields)
    reply = client.call(client.find("SS", f"/hil_control/{service}"),
                        bytes(types.serialize_cdr(request, request.__msgtype__)))
    return types.deserialize_cdr(reply, f"spec/msg/{response_type}")


def _value(types, kind: int, **value):
    import numpy as np
    fields = {"type": kind, "bool_value": False, "integer_value": 0, "double_value": 0.0,
              "string_value": "", "byte_array_value": np.zeros(0, np.uint8),
              "bool_array_value": np.zeros(0, bool), "integer_array_value": np.zeros(0, np.int64),
              "double_array_value": np.zeros(0), "string_array_value": []}
    return types.types["rcl_interfaces/msg/ParameterValue"](**{**fields, **value})


def _set(client, types, name: str, value):
    parameter = types.types["rcl_interfaces/msg/Parameter"](name=name, value=value)
    result, = _ask(client, types, "set_parameters", "SetRequest", "SetResponse",
                   parameters=[parameter]).results
    return result


def test_a_client_lists_reads_and_describes_the_controllers_parameters(client, spec_types):
    listed = _ask(client, spec_types, "list_parameters", "ListRequest", "ListResponse",
                  prefixes=[], depth=0).result
    assert {"joints", "use_sim_time", "constraints.joint1.goal",
            "constraints.joint1.trajectory", "constraints.goal_time",
            "allow_partial_joints_goal"} <= set(listed.names), listed.names
    assert "constraints" in listed.prefixes
    under = _ask(client, spec_types, "list_parameters", "ListRequest", "ListResponse",
                 prefixes=["constraints"], depth=0).result
    assert under.names and all(n.startswith("constraints.") for n in under.names)
    joints, tolerance, unknown = _ask(
        client, spec_types, "get_parameters", "GetRequest", "GetResponse",
        names=["joints", "constraints.joint1.goal", "no_such"]).values
    assert joints.type == STRING_ARRAY and list(joints.string_array_value) == UR3_JOINTS
    assert tolerance.type == DOUBLE and tolerance.double_value == pytest.approx(0.02)
    assert unknown.type == 0
    fixed, settable = _ask(client, spec_types, "describe_parameters", "DescribeRequest",
                           "DescribeResponse",
                           names=["joints", "constraints.joint1.goal"]).descriptors
    assert fixed.read_only and not settable.read_only and settable.type == DOUBLE
    assert "goal" in settable.description


def test_read_only_and_mistyped_parameters_are_refused_with_the_reason(client, spec_types):
    refused = _set(client, spec_types, "joints",
                   _value(spec_types, STRING_ARRAY, string_array_value=["joint1"]))
    assert not refused.successful and "read-only" in refused.reason
    mistyped = _set(client, spec_types, "constraints.joint1.goal",
                    _value(spec_types, STRING, string_value="tight"))
    assert not mistyped.successful and "double" in mistyped.reason
    negative = _set(client, spec_types, "constraints.joint1.goal",
                    _value(spec_types, DOUBLE, double_value=-1.0))
    assert not negative.successful and ">= 0" in negative.reason
    unknown = _set(client, spec_types, "no_such", _value(spec_types, DOUBLE, double_value=1.0))
    assert not unknown.successful and "not declared" in unknown.reason


def _changes(events: list, name: str, value: float) -> bool:
    """Whether a parameter event in ``events`` set ``name`` to ``value``."""
    return any((p.name, p.value.double_value) == (name, value)
               for e in events for p in e.changed_parameters)


def test_a_set_path_tolerance_takes_effect_on_the_next_goal_and_is_announced(client, spec_types,
                                                                               stack):
    name = "constraints.joint3.trajectory"
    events_sub, events = _collect(client, "/parameter_events",
                                  "rcl_interfaces/msg/ParameterEvent")
    try:
        result = _set(client, spec_types, name, _value(spec_types, DOUBLE, double_value=1e-9))
        assert result.successful, result.reason
        value, = _ask(client, spec_types, "get_parameters", "GetRequest", "GetResponse",
                      names=[name]).values
        assert value.double_value == 1e-9
        goal_id = uuid.uuid4().hex
        assert _send(client, _goal_request(goal_id, 1.0, 0.3))
        response = _result(client, goal_id)
        time.sleep(0.2)
    finally:
        _set(client, spec_types, name, _value(spec_types, DOUBLE, double_value=0.0))
        # the set is answered before its event arrives: wait for it (or give up and report)
        deadline = time.monotonic() + 5.0
        while not _changes(events, name, 0.0) and time.monotonic() < deadline:
            time.sleep(0.05)
        events_sub.undeclare()
    # a tracking error of any size breaks a path tolerance of 1 nrad
    assert response.status == ABORTED and response.result.error_code == -4, response
    changed = [(p.name, p.value.double_value) for e in events for p in e.changed_parameters]
    assert (name, 1e-9) in changed and (name, 0.0) in changed, changed
    assert all(e.node == "/hil_control" for e in events)


def test_rosout_carries_a_goals_life_under_the_nodes_logger_name(client):
    rosout_sub, lines = _collect(client, "/rosout", "rcl_interfaces/msg/Log")
    goal_id = uuid.uuid4().hex
    try:
        assert _send(client, _goal_request(goal_id, 0.5, 0.2))
        assert _result(client, goal_id).status == SUCCEEDED
        deadline = time.monotonic() + 5
        while time.monotonic() < deadline and sum(goal_id in l.msg for l in lines) < 2:
            time.sleep(0.05)
    finally:
        rosout_sub.undeclare()
    ours = [(line.level, line.msg) for line in lines if goal_id in line.msg]
    assert [level for level, _ in ours] == [20, 20], ours          # INFO, INFO
    assert "accepted" in ours[0][1] and "joint3" in ours[0][1] and "succeeded" in ours[1][1]
    assert all(line.name == "hil_control" for line in lines)


def _rihs01(description) -> str:
    """REP-2016's hash of a TypeDescription message, as the spec computes it."""
    import hashlib
    import json

    def individual(d):
        return {"type_name": d.type_name, "fields": [
            {"name": f.name, "type": {"type_id": f.type.type_id, "capacity": f.type.capacity,
                                      "string_capacity": f.type.string_capacity,
                                      "nested_type_name": f.type.nested_type_name}}
            for f in d.fields]}
    document = {"type_description": individual(description.type_description),
                "referenced_type_descriptions": [individual(d) for d in
                                                 description.referenced_type_descriptions]}
    return "RIHS01_" + hashlib.sha256(json.dumps(document).encode()).hexdigest()


def test_the_type_description_service_describes_what_the_node_publishes_to_its_hash(
        client, spec_types):
    token = client.find("MP", "/joint_states")
    answer = _ask(client, spec_types, "get_type_description", "TypeRequest", "TypeResponse",
                  type_name="sensor_msgs/msg/JointState", type_hash=token.type_hash,
                  include_type_sources=False)
    assert answer.successful, answer.failure_reason
    described = answer.type_description
    assert described.type_description.type_name == "sensor_msgs/msg/JointState"
    assert [f.name for f in described.type_description.fields] == [
        "header", "name", "position", "velocity", "effort"]
    assert "std_msgs/msg/Header" in [d.type_name for d in described.referenced_type_descriptions]
    assert _rihs01(described) == token.type_hash
    wrong = _ask(client, spec_types, "get_type_description", "TypeRequest", "TypeResponse",
                 type_name="sensor_msgs/msg/JointState", type_hash="RIHS01_" + "0" * 64,
                 include_type_sources=False)
    assert not wrong.successful and token.type_hash in wrong.failure_reason
    unused = _ask(client, spec_types, "get_type_description", "TypeRequest", "TypeResponse",
                  type_name="sensor_msgs/msg/Image", type_hash="", include_type_sources=False)
    assert not unused.successful and "uses no type" in unused.failure_reason


def test_controller_manager_lists_and_switches_the_controllers_over_ros(client):
    """controller_manager's services as `ros2 control` calls them (controller_manager_msgs,
    jazzy), and forward_command_controller's ~/commands topics in the graph."""
    listed = cdr.decode(client.call(client.find("SS", "/controller_manager/list_controllers"),
                                    cdr.EMPTY_REQUEST), cdr.LIST_CONTROLLERS_RESPONSE)
    states = {c.name: (c.state, c.type) for c in listed.controller}
    assert states["joint_trajectory_controller"] == (
        "active", "joint_trajectory_controller/JointTrajectoryController")
    assert states["forward_position_controller"][0] == "inactive"
    client.find("MS", "/forward_position_controller/commands")
    switch = client.find("SS", "/controller_manager/switch_controller")

    def request(activate, deactivate, strictness=2):
        response = cdr.decode(client.call(switch, cdr.encode(cdr.msg(
            cdr.SWITCH_CONTROLLER_REQUEST, activate_controllers=activate,
            deactivate_controllers=deactivate, strictness=strictness, activate_asap=False,
            timeout=cdr.duration_msg(0.0)))), cdr.SWITCH_CONTROLLER_RESPONSE)
        return response.ok, response.message
    ok, message = request([], ["joint_trajectory_controller"])
    assert not ok and "without a controller" in message
    assert request(["forward_position_controller"], ["joint_trajectory_controller"]) == (
        True, "Successfully switched controllers!")
    assert request(["joint_trajectory_controller"], ["forward_position_controller"]) == (
        True, "Successfully switched controllers!")
