"""The FollowJointTrajectory action on Zenoh (keys: :mod:`hil.messaging.keys`): the
server around a JointTrajectoryController, and the client ``hil send`` and scripts use.
Payloads are ROS 2 CDR of the action's messages."""

from __future__ import annotations

import logging
import queue
import re
import threading
import time
import uuid
from collections.abc import Callable

import numpy as np
import zenoh

from hil.controllers import (
    INVALID_GOAL, ControllerState, GoalRejected, GoalResult, GoalStatus,
    JointTrajectoryController, TrajectoryGoal,
)
from hil.messaging import cdr
from hil.messaging.keys import ACTION, ask, direct, key
from hil.realtime import enter_side_work, paused_collection, release_gradually

log = logging.getLogger(__name__)

#: the largest goal request taken (CDR bytes): 16 MiB, over 200,000 points of 6 joints
#: (the controller takes at most MAX_POINTS of them)
MAX_GOAL_BYTES = 16 * 2 ** 20

#: finished goals' results a server keeps for get_result (the oldest go first)
KEPT_RESULTS = 1000


class TrajectoryActionServer:
    """Serves a JointTrajectoryController's FollowJointTrajectory action on Zenoh."""

    def __init__(self, session: zenoh.Session, robot: str, controller: JointTrajectoryController,
                 stamp_to_clock: Callable[[float], float]):
        """``stamp_to_clock``: a goal's header stamp on the controller's clock."""
        self.session, self.robot, self.controller = session, robot, controller
        self.stamp_to_clock = stamp_to_clock
        self._results: dict[str, GoalResult] = {}
        self._lock = threading.Lock()
        #: answers a fault reset: () -> (succeeded, message); set by the control loop
        self.on_reset: Callable[[], tuple[bool, str]] | None = None
        prefix = key(robot, ACTION)
        self._feedback = session.declare_publisher(f"{prefix}/feedback")
        self._result = session.declare_publisher(f"{prefix}/result")
        self._warm_up()
        self._queryables = [
            session.declare_queryable(f"{prefix}/send_goal", self._on_send_goal),
            session.declare_queryable(f"{prefix}/cancel_goal", self._on_cancel),
            session.declare_queryable(f"{prefix}/get_result", self._on_get_result),
            session.declare_queryable(key(robot, "reset_faults"), self._on_reset),
        ]

    def _warm_up(self) -> None:
        """Encode each message type once: rosbags builds its codecs on first use, which
        would otherwise stall the first control cycles that publish."""
        names = list(self.controller.joint_names)
        zeros = np.zeros(len(names))
        cdr.encode(cdr.joint_state_msg(0.0, names, zeros, zeros, zeros))
        cdr.encode(cdr.result_msg("00" * 16, GoalResult(GoalStatus.SUCCEEDED, 0)))
        encode_feedback_once(names)

    def _on_send_goal(self, query: zenoh.Query) -> None:
        try:
            submit_goal_request(self.controller.submit, self.stamp_to_clock, _payload(query))
        except (ValueError, GoalRejected) as exc:
            code = getattr(exc, "error_code", -1)
            query.reply_err(f"rejected ({code}): {exc}")
            return
        except Exception as exc:        # a hil defect: the client still hears why, at once
            log.exception("goal refused on an unexpected error")
            query.reply_err(f"rejected (-1): the controller failed on this goal ({exc!r}): a "
                            "hil defect; its log has the traceback")
            return
        query.reply(query.key_expr, cdr.encode(cdr.msg(cdr.SEND_GOAL_RESPONSE, accepted=True,
                                                     stamp=cdr.time_msg(time.time()))))

    def _on_cancel(self, query: zenoh.Query) -> None:
        enter_side_work()
        request = _decode_or_reply_error(query, cdr.CANCEL_REQUEST)
        if request is None:
            return
        goal_id = cdr.goal_id_of(request.goal_info.goal_id)
        canceled = self.controller.cancel(goal_id)
        query.reply(query.key_expr, cdr.encode(cdr.msg(
            cdr.CANCEL_RESPONSE, return_code=0 if canceled else 2,   # 2: ERROR_UNKNOWN_GOAL_ID
            goals_canceling=[request.goal_info] if canceled else [])))

    def _on_get_result(self, query: zenoh.Query) -> None:
        enter_side_work()
        request = _decode_or_reply_error(query, cdr.GET_RESULT_REQUEST)
        if request is None:
            return
        with self._lock:
            result = self._results.get(cdr.goal_id_of(request.goal_id))
        if result is None:
            query.reply_err("no result (yet) for that goal")
            return
        query.reply(query.key_expr, cdr.encode(cdr.result_msg(cdr.goal_id_of(request.goal_id), result)))

    def _on_reset(self, query: zenoh.Query) -> None:
        enter_side_work()
        if self.on_reset is None:
            query.reply_err("this controller cannot reset faults")
            return
        succeeded, message = self.on_reset()
        query.reply(query.key_expr, cdr.encode(cdr.msg(cdr.TRIGGER_RESPONSE, success=succeeded,
                                                         message=message)))

    def put_feedback(self, payload: bytes) -> None:
        """Put the active goal's FeedbackMessage (:func:`feedback_message`, encoded)."""
        self._feedback.put(payload)

    def publish_results(self, finished: list[tuple[str, GoalResult]]) -> None:
        """Publish (and keep for get_result) the results of goals that ended: the last
        KEPT_RESULTS, as a ROS action server keeps its results for a bounded time (rcl_action's
        result_timeout; a count here, as goals come at any rate)."""
        for goal_id, result in finished:
            with self._lock:
                self._results[goal_id] = result
                while len(self._results) > KEPT_RESULTS:
                    del self._results[next(iter(self._results))]      # the oldest
            self._result.put(cdr.encode(cdr.result_msg(goal_id, result)))

    def close(self) -> None:
        for queryable in self._queryables:
            queryable.undeclare()
        self._feedback.undeclare()
        self._result.undeclare()


def encode_feedback_once(joint_names, types=cdr.TYPES) -> None:
    """Encode a FeedbackMessage of these joints once, as ``types`` lays it out: rosbags
    builds each codec on first use, which would otherwise stall the control cycle that
    publishes the first feedback."""
    zeros = np.zeros(len(joint_names))
    cdr.encode(feedback_message(ControllerState(0.0, tuple(joint_names), zeros, zeros, zeros,
                                                zeros, "00" * 16), 0.0, types), types)


def feedback_message(state: ControllerState, stamp: float, types=cdr.TYPES):
    """The active goal's FeedbackMessage (``state.goal_id`` set), stamped ``stamp``, as
    ``types`` lays it out: with control_msgs 6's point indices where its Feedback has them
    (``types``: see :func:`hil.messaging.cdr.encode`)."""
    feedback_type = types.types["control_msgs/action/FollowJointTrajectory_Feedback"]
    indices = ({"index": state.point_index, "multi_dof_index": 0}
               if "index" in feedback_type.__dataclass_fields__ else {})
    feedback = feedback_type(
        header=cdr.header(stamp), joint_names=list(state.joint_names),
        desired=cdr.point_msg(state.desired_positions, state.desired_velocities),
        actual=cdr.point_msg(state.actual_positions, state.actual_velocities),
        error=cdr.point_msg(state.errors,
                            state.desired_velocities - state.actual_velocities),
        multi_dof_joint_names=[], multi_dof_desired=_empty_multi_dof(),
        multi_dof_actual=_empty_multi_dof(), multi_dof_error=_empty_multi_dof(), **indices)
    return types.types[cdr.FEEDBACK_MESSAGE](goal_id=cdr.uuid_msg(state.goal_id),
                                             feedback=feedback)


def submit_goal_request(submit: Callable[[str, TrajectoryGoal], None],
                        stamp_to_clock: Callable[[float], float], payload: bytes) -> str:
    """Decode a FollowJointTrajectory SendGoal request and hand its goal to ``submit`` (a
    controller's :meth:`~JointTrajectoryController.submit`, or a server's wrapper of it),
    its header stamp (0: now) put on the controller's clock by ``stamp_to_clock``; the
    goal's id. Raises GoalRejected (with the controller's reason) or ValueError.

    A large goal is a burst of Python objects in the calling (Zenoh) thread: decoded below
    the frame handling's priority, with the collector paused and freed a chunk at a time,
    it never holds the control loop or the frames for long (hil.realtime)."""
    enter_side_work()
    with paused_collection():
        if len(payload) > MAX_GOAL_BYTES:
            raise GoalRejected(f"the goal is {len(payload)} bytes; this controller takes "
                               f"at most {MAX_GOAL_BYTES} (split it into several goals)")
        request = cdr.decode(payload, cdr.SEND_GOAL_REQUEST)
        goal_id = cdr.goal_id_of(request.goal_id)
        stamp = cdr.seconds_of(request.goal.trajectory.header.stamp)
        start = None if stamp == 0 else stamp_to_clock(stamp)
        goal = cdr.goal_from_msg(request.goal, start)
        release_gradually(request.goal.trajectory.points)
        submit(goal_id, goal)
        log.info("goal %s accepted: %d point(s) for %s, %.3g s", goal_id, len(goal.points),
                 ", ".join(goal.joint_names), goal.points[-1].time_from_start)
        return goal_id


def _decode_or_reply_error(query: zenoh.Query, typename: str):
    """The query's request, or None after answering a malformed one with an error."""
    try:
        return cdr.decode(_payload(query), typename)
    except ValueError as exc:
        query.reply_err(str(exc))
        return None


def _payload(query: zenoh.Query) -> bytes:
    if query.payload is None:
        raise ValueError("the query carries no payload")
    return query.payload.to_bytes()


def _empty_multi_dof():
    return cdr.msg("trajectory_msgs/msg/MultiDOFJointTrajectoryPoint", transforms=[],
                   velocities=[], accelerations=[], time_from_start=cdr.duration_msg(0.0))


class ControllerGone(RuntimeError):
    """The controller process disappeared (its liveliness token went away)."""


class WaitStopped(Exception):
    """A wait for a goal's result given up because its caller's ``stop`` event was set (the
    goal still runs: the caller decides whether to cancel it)."""


class TrajectoryActionClient:
    """Sends FollowJointTrajectory goals to a hil controller over Zenoh. A context manager:
    ``with TrajectoryActionClient(session, "ur3") as client: ...`` closes it."""

    def __init__(self, session: zenoh.Session, robot: str):
        self.session, self.robot = session, robot
        prefix = key(robot, ACTION)
        self._prefix = prefix
        self._results: "queue.Queue[tuple[str, GoalResult]]" = queue.Queue()
        self._feedback: "queue.Queue" = queue.Queue()
        # callbacks in Zenoh's own threads (not indirect): an indirect callback runs in a
        # Python thread of its own that is not a daemon, and a script that ended without
        # close() waited for those threads at exit (60 s, measured)
        self._subscribers = [
            session.declare_subscriber(f"{prefix}/result", direct(self._on_result)),
            session.declare_subscriber(f"{prefix}/feedback", direct(self._on_feedback)),
        ]
        self._alive = threading.Event()
        self._gone = threading.Event()
        self._liveliness = session.liveliness().declare_subscriber(
            key(robot, "control"), direct(self._on_liveliness), history=True)

    def _on_liveliness(self, sample: zenoh.Sample) -> None:
        if sample.kind == zenoh.SampleKind.PUT:
            self._alive.set()
            self._gone.clear()
        else:
            self._alive.clear()
            self._gone.set()

    def _on_result(self, sample: zenoh.Sample) -> None:
        try:
            message = cdr.decode(sample.payload.to_bytes(), cdr.GOAL_RESULT)
        except ValueError:
            return
        self._results.put((cdr.goal_id_of(message.goal_id), cdr.result_from_msg(message)))

    def _on_feedback(self, sample: zenoh.Sample) -> None:
        try:
            self._feedback.put(cdr.decode(sample.payload.to_bytes(), cdr.FEEDBACK_MESSAGE))
        except ValueError:
            pass

    def wait_for_controller(self, timeout: float) -> bool:
        return self._alive.wait(timeout)

    def send_goal(self, goal: TrajectoryGoal, start_stamp: float = 0.0,
                  timeout: float = 5.0) -> str:
        """Send a goal; return its id, or raise GoalRejected with the controller's reason."""
        goal_id = uuid.uuid4().hex
        request = cdr.encode(cdr.msg(cdr.SEND_GOAL_REQUEST, goal_id=cdr.uuid_msg(goal_id),
                                     goal=cdr.goal_msg(goal, start_stamp)))
        return self._query("send_goal", request, timeout, goal_id)

    def send_raw(self, payload: bytes, timeout: float = 5.0) -> str:
        """Send arbitrary bytes as a goal request (for testing the server's defences)."""
        return self._query("send_goal", payload, timeout, "")

    def _query(self, name: str, payload: bytes, timeout: float, goal_id: str) -> str:
        replies = ask(self.session, f"{self._prefix}/{name}", payload, timeout)
        if not replies:
            raise ControllerGone(f"no controller answered on {self._prefix}/{name} within "
                                 f"{timeout:g} s")
        reply = replies[0]
        if reply.err is not None:
            text = reply.err.payload.to_bytes().decode(errors="replace")
            code = re.match(r"rejected \((-?\d+)\): ", text)     # the server's own words
            raise GoalRejected(text, int(code[1]) if code else INVALID_GOAL)
        return goal_id

    def cancel(self, goal_id: str, timeout: float = 5.0) -> bool:
        """Ask the controller to cancel a goal: True if it did, False if it does not run
        that goal (ended, or never known); ControllerGone if no controller answered."""
        info = cdr.msg("action_msgs/msg/GoalInfo", goal_id=cdr.uuid_msg(goal_id),
                       stamp=cdr.time_msg(0.0))
        replies = ask(self.session, f"{self._prefix}/cancel_goal",
                      cdr.encode(cdr.msg(cdr.CANCEL_REQUEST, goal_info=info)), timeout)
        if not replies:
            raise ControllerGone(f"no controller answered on {self._prefix}/cancel_goal "
                                 f"within {timeout:g} s")
        if replies[0].err is not None:
            return False
        return cdr.decode(replies[0].ok.payload.to_bytes(), cdr.CANCEL_RESPONSE).return_code == 0

    def reset_faults(self, timeout: float = 15.0) -> tuple[bool, str]:
        """Ask the controller to reset drive faults; (succeeded, what happened)."""
        replies = ask(self.session, key(self.robot, "reset_faults"), None, timeout)
        if not replies:
            raise ControllerGone(f"no controller answered on {key(self.robot, 'reset_faults')}")
        if replies[0].err is not None:
            return False, replies[0].err.payload.to_bytes().decode(errors="replace")
        response = cdr.decode(replies[0].ok.payload.to_bytes(), cdr.TRIGGER_RESPONSE)
        return response.success, response.message

    def wait_result(self, goal_id: str, timeout: float, on_feedback: Callable | None = None,
                    stop: threading.Event | None = None) -> GoalResult:
        """Wait for a goal's result; raise ControllerGone if the controller dies first,
        WaitStopped once ``stop`` is set (seen within 50 ms)."""
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            if stop is not None and stop.is_set():
                raise WaitStopped(f"stopped waiting for goal {goal_id[:8]}")
            while not self._feedback.empty():        # drained even when nobody looks at it
                feedback = self._feedback.get_nowait()
                if on_feedback is not None and cdr.goal_id_of(feedback.goal_id) == goal_id:
                    on_feedback(feedback.feedback)
            try:
                done_id, result = self._results.get(timeout=0.05)
            except queue.Empty:
                if self._gone.is_set():
                    raise ControllerGone(f"the controller for '{self.robot}' went away "
                                         f"(liveliness lost) before goal {goal_id[:8]} ended")
                continue
            if done_id == goal_id:
                return result
        raise TimeoutError(f"no result for goal {goal_id[:8]} within {timeout:g} s")

    def close(self) -> None:
        for subscriber in self._subscribers:
            subscriber.undeclare()
        self._liveliness.undeclare()

    def __enter__(self) -> TrajectoryActionClient:
        return self

    def __exit__(self, *exc_info) -> None:
        self.close()


__all__ = ["ControllerGone", "MAX_GOAL_BYTES", "TrajectoryActionClient",
           "TrajectoryActionServer", "submit_goal_request"]
