"""The ROS 2 action server's bookkeeping on its own (no Zenoh): goals and their results."""

from __future__ import annotations

import queue
import time
import types
import uuid

from hil.controllers import GoalResult, GoalStatus, TrajectoryGoal, TrajectoryPoint
from hil.messaging import cdr
from hil.messaging.ros.action import RosGoalStatus, RosTrajectoryActionServer


class Declared:
    def put(self, payload: bytes) -> None:
        pass

    def close(self) -> None:
        pass


class Node:
    """What the server declares on a node, declared nowhere."""

    def publisher(self, *args, **kwargs) -> Declared:
        return Declared()

    def service(self, *args, **kwargs) -> Declared:
        return Declared()


class Request:
    """A service request whose answer lands in ``answers``."""

    def __init__(self, payload: bytes):
        self.payload = payload
        self.answers: queue.SimpleQueue = queue.SimpleQueue()

    def reply(self, payload: bytes) -> None:
        self.answers.put(payload)

    def reply_error(self, text: str) -> None:
        self.answers.put(text)


class GoalEndingAtOnce:
    """A controller that ends each goal as it takes it, as a path tolerance broken in the
    goal's first cycle does, and is slow to return (the Zenoh thread preempted): the
    result reaches the server while it is still taking the goal."""

    def __init__(self):
        self.server: RosTrajectoryActionServer | None = None

    def submit(self, goal_id: str, goal: TrajectoryGoal) -> None:
        self.server.record_results([(goal_id, GoalResult(GoalStatus.ABORTED, -4, "path"))])
        time.sleep(0.2)


def test_a_goal_that_ends_while_it_is_being_accepted_still_gets_its_result():
    controller = GoalEndingAtOnce()
    interfaces = types.SimpleNamespace(status=None, feedback=None, send_goal=None,
                                       cancel_goal=None, get_result=None)
    server = RosTrajectoryActionServer(Node(), "/jtc/follow_joint_trajectory", interfaces,
                                       controller, clock=time.monotonic)
    controller.server = server
    try:
        goal_id = uuid.uuid4().hex
        goal = TrajectoryGoal(("joint3",), (TrajectoryPoint(1.0, (0.3,), (0.0,)),))
        send = Request(cdr.encode(cdr.msg(cdr.SEND_GOAL_REQUEST, goal_id=cdr.uuid_msg(goal_id),
                                          goal=cdr.goal_msg(goal))))
        server._on_send_goal(send)
        assert cdr.decode(send.answers.get(timeout=5), cdr.SEND_GOAL_RESPONSE).accepted
        ask = Request(cdr.encode(cdr.msg(cdr.GET_RESULT_REQUEST, goal_id=cdr.uuid_msg(goal_id))))
        server._on_get_result(ask)
        response = cdr.decode(ask.answers.get(timeout=5), cdr.GET_RESULT_RESPONSE)
        assert response.status == RosGoalStatus.ABORTED
        assert response.result.error_code == -4
    finally:
        server.close()
