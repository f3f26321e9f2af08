"""control_msgs/action/FollowJointTrajectory as an rcl action server and client over
rmw_zenoh: three services (``_action/send_goal``, ``cancel_goal``, ``get_result``) and two
topics (``_action/feedback``, ``_action/status``), with rcl_action's goal states.

The server is an adapter: goals go to hil's JointTrajectoryController through the same
path as hil's own action (:func:`hil.messaging.action.submit_goal_request`), results come
from the control loop (:meth:`RosTrajectoryActionServer.record_results`).
"""

from __future__ import annotations

import enum
import logging
import queue
import threading
import time
import uuid
from collections.abc import Callable
from dataclasses import dataclass

from hil.controllers import GoalRejected, GoalResult, GoalStatus, TrajectoryGoal
from hil.messaging import cdr
from hil.messaging.action import WaitStopped, submit_goal_request
from hil.messaging.ros.interfaces import FollowJointTrajectory, distro_types
from hil.messaging.ros.node import NO_LIMIT, RosNode, ServiceError, ServiceRequest
from hil.messaging.ros.rmw_zenoh import ACTION_STATUS_QOS
from hil.realtime import enter_side_work

log = logging.getLogger(__name__)

#: how long a finished goal's result stays available (rcl_action's default result_timeout)
RESULT_TIMEOUT = 900.0
ZERO_ID = "00" * 16
STATUS_ARRAY = "action_msgs/msg/GoalStatusArray"


class RosGoalStatus(enum.IntEnum):     # action_msgs/msg/GoalStatus
    UNKNOWN = 0
    ACCEPTED = 1
    EXECUTING = 2
    CANCELING = 3
    SUCCEEDED = 4
    CANCELED = 5
    ABORTED = 6


class CancelCode(enum.IntEnum):        # action_msgs/srv/CancelGoal return codes
    NONE = 0
    REJECTED = 1
    UNKNOWN_GOAL_ID = 2
    GOAL_TERMINATED = 3


def ros_status(status: GoalStatus) -> RosGoalStatus:
    """A goal's terminal state as action_msgs numbers it (hil's REJECTED, a goal that never
    became active, is ABORTED there)."""
    return RosGoalStatus.ABORTED if status is GoalStatus.REJECTED else RosGoalStatus(status.value)


@dataclass
class _Goal:
    goal_id: str
    accepted: float                       # ROS time (the server's ros_time)
    status: RosGoalStatus
    result: GoalResult | None = None
    finished: float = 0.0                 # wall-clock time, for how long it is kept


class RosTrajectoryActionServer:
    """Serves a JointTrajectoryController as ``<node namespace>/<name>`` (e.g.
    ``/joint_trajectory_controller/follow_joint_trajectory``)."""

    def __init__(self, node: RosNode, name: str, interfaces: FollowJointTrajectory,
                 controller, clock: Callable[[], float],
                 on_rejected: Callable[[str], None] | None = None,
                 ros_time: Callable[[], float] = time.time):
        """``clock``: the controller's; ``ros_time``: the node's ROS time (s since the
        epoch, or the plant's time with use_sim_time), which stamps goals as rcl_action
        does (accepted goals, cancel requests by time)."""
        self.controller, self.clock, self.on_rejected = controller, clock, on_rejected
        self.ros_time = ros_time
        self._goals: dict[str, _Goal] = {}
        self._waiting: dict[str, list[ServiceRequest]] = {}   # get_result before the end
        self._lock = threading.Lock()
        self._results: queue.SimpleQueue = queue.SimpleQueue()
        prefix = f"{name}/_action"
        self._status = node.publisher(f"{prefix}/status", interfaces.status, ACTION_STATUS_QOS)
        #: the action's feedback publisher (FeedbackMessage CDR bytes, put by the caller)
        self.feedback = node.publisher(f"{prefix}/feedback", interfaces.feedback)
        self._services = [
            node.service(f"{prefix}/send_goal", interfaces.send_goal, self._on_send_goal),
            node.service(f"{prefix}/cancel_goal", interfaces.cancel_goal, self._on_cancel),
            node.service(f"{prefix}/get_result", interfaces.get_result, self._on_get_result),
        ]
        self._publish_status()
        self._worker = threading.Thread(target=self._finish_goals, daemon=True,
                                        name="ros-action-results")
        self._worker.start()

    # --- from the control loop ----------------------------------------------------------

    def record_results(self, finished: list[tuple[str, GoalResult]]) -> None:
        """Goals that ended this cycle; answered in a thread of this server's own."""
        if finished:
            self._results.put(finished)

    # --- services (Zenoh's threads) -----------------------------------------------------

    def _on_send_goal(self, request: ServiceRequest) -> None:
        try:
            goal_id = submit_goal_request(self._submit, self._stamp_to_clock, request.payload)
        except (ValueError, GoalRejected) as exc:
            # rcl's answer carries no reason: it goes to the log and to on_rejected
            log.warning("FollowJointTrajectory goal rejected: %s", exc)
            if self.on_rejected is not None:
                self.on_rejected(f"goal rejected: {exc}")
            request.reply(cdr.encode(cdr.msg(cdr.SEND_GOAL_RESPONSE, accepted=False,
                                             stamp=cdr.time_msg(self.ros_time()))))
            return
        with self._lock:
            accepted = self._goals[goal_id].accepted
        request.reply(cdr.encode(cdr.msg(cdr.SEND_GOAL_RESPONSE, accepted=True,
                                         stamp=cdr.time_msg(accepted))))

    def _stamp_to_clock(self, stamp: float) -> float:
        """A goal's header stamp (ROS time) on the controller's clock."""
        return self.clock() + (stamp - self.ros_time())

    def _submit(self, goal_id: str, goal: TrajectoryGoal) -> None:
        """The controller's submit, with the goal known to this server in the same breath:
        under the lock that results are recorded under, so that a goal ending in its first
        cycle (a path tolerance broken at once) is already this server's when its result
        comes (it was dropped as another server's, and its get_result never answered)."""
        now = self.ros_time()
        with self._lock:
            self.controller.submit(goal_id, goal)
            # rcl_action: ACCEPTED, then EXECUTING once the server runs it, which the
            # controller already does
            self._goals[goal_id] = _Goal(goal_id, now, RosGoalStatus.EXECUTING)
            self._publish_status_locked()

    def _on_cancel(self, request: ServiceRequest) -> None:
        try:
            info = cdr.decode(request.payload, cdr.CANCEL_REQUEST).goal_info
        except ValueError as exc:
            request.reply_error(str(exc))
            return
        goal_id, before = cdr.goal_id_of(info.goal_id), cdr.seconds_of(info.stamp)
        with self._lock:
            chosen = [g for g in self._goals.values()
                      if (goal_id != ZERO_ID and g.goal_id == goal_id)
                      or (goal_id == ZERO_ID and before == 0.0)
                      or (before != 0.0 and g.accepted <= before)]
            canceling = [g for g in chosen if g.result is None]
            for goal in canceling:
                goal.status = RosGoalStatus.CANCELING
            if canceling:
                self._publish_status_locked()
        canceling = [g for g in canceling if self.controller.cancel(g.goal_id)]
        if canceling:
            code = CancelCode.NONE
        elif goal_id != ZERO_ID and goal_id not in self._goals:
            code = CancelCode.UNKNOWN_GOAL_ID
        elif chosen:
            code = CancelCode.GOAL_TERMINATED
        else:
            code = CancelCode.REJECTED
        request.reply(cdr.encode(cdr.msg(cdr.CANCEL_RESPONSE, return_code=int(code),
                                         goals_canceling=[_goal_info(g) for g in canceling])))

    def _on_get_result(self, request: ServiceRequest) -> None:
        try:
            goal_id = cdr.goal_id_of(cdr.decode(request.payload, cdr.GET_RESULT_REQUEST).goal_id)
        except ValueError as exc:
            request.reply_error(str(exc))
            return
        with self._lock:
            goal = self._goals.get(goal_id)
            if goal is not None and goal.result is None:
                self._waiting.setdefault(goal_id, []).append(request)    # answered at the end
                return
        request.reply(_result_response(goal))

    # --- results ------------------------------------------------------------------------

    def _finish_goals(self) -> None:
        enter_side_work()           # in a real-time process: below its loop and frames
        while True:
            finished = self._results.get()
            if finished is None:
                return
            now = time.time()
            with self._lock:
                answers = []
                for goal_id, result in finished:
                    goal = self._goals.get(goal_id)
                    if goal is None:          # a goal of hil's own action, not of this server
                        continue
                    goal.status, goal.result, goal.finished = ros_status(result.status), result, now
                    log.log(logging.INFO if goal.status is RosGoalStatus.SUCCEEDED
                            else logging.WARNING, "goal %s %s%s", goal_id,
                            goal.status.name.lower(),
                            f": {result.error_string}" if result.error_string else "")
                    answers += [(r, goal) for r in self._waiting.pop(goal_id, [])]
                for goal_id in [g.goal_id for g in self._goals.values()
                                if g.result is not None and now - g.finished > RESULT_TIMEOUT]:
                    del self._goals[goal_id]
                self._publish_status_locked()
            for request, goal in answers:
                request.reply(_result_response(goal))

    def _publish_status(self) -> None:
        with self._lock:
            self._publish_status_locked()

    def _publish_status_locked(self) -> None:
        statuses = [cdr.msg("action_msgs/msg/GoalStatus", goal_info=_goal_info(g),
                            status=int(g.status)) for g in self._goals.values()]
        self._status.put(cdr.encode(cdr.msg(STATUS_ARRAY, status_list=statuses)))

    def close(self) -> None:
        """Stop: results still awaited are answered as the controller left the goals
        (aborted on shutdown, through record_results), the rest with an error."""
        self._results.put(None)
        self._worker.join(5.0)
        for service in self._services:
            service.close()


def _goal_info(goal: _Goal):
    return cdr.msg("action_msgs/msg/GoalInfo", goal_id=cdr.uuid_msg(goal.goal_id),
                   stamp=cdr.time_msg(goal.accepted))


def _result_response(goal: _Goal | None) -> bytes:
    """GetResult's response: status UNKNOWN and an empty result for a goal not known."""
    if goal is None or goal.result is None:
        status, code, text = RosGoalStatus.UNKNOWN, 0, ""
    else:
        status, code, text = goal.status, goal.result.error_code, goal.result.error_string
    return cdr.encode(cdr.msg(cdr.GET_RESULT_RESPONSE, status=int(status), result=cdr.msg(
        "control_msgs/action/FollowJointTrajectory_Result", error_code=code,
        error_string=text)))


class RosTrajectoryActionClient:
    """Sends FollowJointTrajectory goals to any rcl action server on rmw_zenoh (hil's ROS
    face or a ros2_control joint_trajectory_controller)."""

    def __init__(self, node: RosNode, name: str, interfaces: FollowJointTrajectory):
        prefix = f"{name}/_action"
        self.name = name
        self._send = node.client(f"{prefix}/send_goal", interfaces.send_goal)
        self._cancel = node.client(f"{prefix}/cancel_goal", interfaces.cancel_goal)
        self._result = node.client(f"{prefix}/get_result", interfaces.get_result)
        self._types = distro_types(interfaces.distro)
        self._feedback: queue.SimpleQueue = queue.SimpleQueue()
        self._feedback_subscription = node.subscription(
            f"{prefix}/feedback", interfaces.feedback,
            lambda payload, attachment: self._feedback.put(payload))

    def send_goal(self, goal: TrajectoryGoal, start_stamp: float = 0.0,
                  timeout: float = 10.0) -> str:
        """Send a goal; its id, or GoalRejected (rcl gives no reason) or ServiceError."""
        goal_id = uuid.uuid4().hex
        payload, _ = self._send.call(cdr.encode(cdr.msg(
            cdr.SEND_GOAL_REQUEST, goal_id=cdr.uuid_msg(goal_id),
            goal=cdr.goal_msg(goal, start_stamp))), timeout)
        if not cdr.decode(payload, cdr.SEND_GOAL_RESPONSE).accepted:
            raise GoalRejected(f"{self.name} rejected the goal (ROS 2 actions give no reason; "
                               "the server's log says why)")
        return goal_id

    def cancel(self, goal_id: str, timeout: float = 10.0) -> bool:
        info = cdr.msg("action_msgs/msg/GoalInfo", goal_id=cdr.uuid_msg(goal_id),
                       stamp=cdr.time_msg(0.0))
        payload, _ = self._cancel.call(cdr.encode(cdr.msg(cdr.CANCEL_REQUEST, goal_info=info)),
                                       timeout)
        return cdr.decode(payload, cdr.CANCEL_RESPONSE).return_code == CancelCode.NONE

    def wait_result(self, goal_id: str, timeout: float = NO_LIMIT,
                    on_feedback: Callable | None = None,
                    stop: threading.Event | None = None) -> GoalResult:
        """The goal's result (get_result, answered when the goal ends); WaitStopped once
        ``stop`` is set (seen within 50 ms)."""
        answer: queue.Queue = queue.Queue()  # not SimpleQueue: see hil.visualisation.node
        request = cdr.encode(cdr.msg(cdr.GET_RESULT_REQUEST, goal_id=cdr.uuid_msg(goal_id)))
        caller = threading.Thread(target=lambda: answer.put(_call(self._result, request,
                                                                  timeout)), daemon=True)
        caller.start()
        while True:
            if stop is not None and stop.is_set():
                raise WaitStopped(f"stopped waiting for goal {goal_id[:8]}")
            while not self._feedback.empty():
                feedback = cdr.decode(self._feedback.get(), cdr.FEEDBACK_MESSAGE, self._types)
                if on_feedback is not None and cdr.goal_id_of(feedback.goal_id) == goal_id:
                    on_feedback(feedback.feedback)
            try:
                outcome = answer.get(timeout=0.05)
                break
            except queue.Empty:
                continue
        if isinstance(outcome, Exception):
            raise outcome
        response = cdr.decode(outcome, cdr.GET_RESULT_RESPONSE)
        status = RosGoalStatus(response.status)
        if status not in (RosGoalStatus.SUCCEEDED, RosGoalStatus.CANCELED, RosGoalStatus.ABORTED):
            raise ServiceError(f"{self.name}: goal {goal_id[:8]} has status {status.name}")
        return GoalResult(GoalStatus(int(status)), response.result.error_code,
                          response.result.error_string)

    def close(self) -> None:
        for entity in (self._feedback_subscription, self._send, self._cancel, self._result):
            entity.close()

    def __enter__(self) -> RosTrajectoryActionClient:
        return self

    def __exit__(self, *exc_info) -> None:
        self.close()


def _call(client, payload: bytes, timeout: float):
    try:
        return client.call(payload, timeout)[0]
    except ServiceError as exc:
        return exc


__all__ = ["RESULT_TIMEOUT", "RosGoalStatus", "RosTrajectoryActionClient",
           "RosTrajectoryActionServer", "ros_status"]
