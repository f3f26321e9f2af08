"""hil's Zenoh key expressions, all under ``hil/<robot>/``:

=====================================================  ==========================================
``joint_states``                                       publication, sensor_msgs/JointState
``sensors/<name>/imu``                                 publication, sensor_msgs/Imu: an IMU's
                                                       samples as the controller reads them
``sensors/<name>/wrench``                              publication, geometry_msgs/WrenchStamped:
                                                       a force-torque sensor's, as it polls it
``follow_joint_trajectory/_action/send_goal``          query: SendGoal_Request -> SendGoal_Response
                                                       (rejection: error reply with the reason)
``follow_joint_trajectory/_action/cancel_goal``        query: action_msgs CancelGoal
``follow_joint_trajectory/_action/get_result``         query: GetResult_Request -> GetResult_Response
``follow_joint_trajectory/_action/feedback``           publication, FeedbackMessage
``follow_joint_trajectory/_action/result``             publication, hil_msgs/GoalResult
``control/samples``                                    publication, hil_msgs/ControlSamples: every
                                                       control cycle, in batches (10 Hz)
``sim/clock``                                          publication, hil_msgs/SimClock (20 Hz)
``diagnostics``                                        publication, diagnostic_msgs/DiagnosticArray:
                                                       the controller's faults (ERROR) and
                                                       fault resets (OK), as they happen
``reset_faults``                                       query (no payload) -> std_srvs/Trigger response:
                                                       reset drive faults, hold, accept goals again
``controller_manager/list_controllers``, ``..._switch``  queries: the controllers, a switch
                                                       (hil.messaging.controller_manager)
``<controller>/commands``                              query: a forward controller's command
``control``, ``sim``, ``viz``                          liveliness tokens of the processes
=====================================================  ==========================================

A malformed payload is answered with an error reply naming what was wrong;
it never reaches the controller.
"""

from __future__ import annotations

import time
from collections.abc import Callable

import zenoh

#: what a sensor's key ends in, by its kind: an IMU's sensor_msgs/Imu, a force-torque
#: sensor's geometry_msgs/WrenchStamped
IMU, WRENCH = "imu", "wrench"


def sensor_key(name: str, kind: str) -> str:
    """The key of sensor ``name``'s samples of ``kind`` (IMU, WRENCH), under ``hil/<robot>/``."""
    return f"sensors/{name}/{kind}"


#: the FollowJointTrajectory action's keys, under ``hil/<robot>/``
ACTION = "follow_joint_trajectory/_action"
#: a query that met no one is asked again after this long (s); the least a query waits (s)
ASK_AGAIN, MIN_WAIT = 0.05, 0.01


def key(robot: str, name: str) -> str:
    """The key expression of ``name`` for ``robot``."""
    return f"hil/{robot}/{name}"


def direct(callback: Callable[[zenoh.Sample], None]) -> zenoh.handlers.Callback:
    """A Zenoh callback run in Zenoh's receiving thread (for short callbacks only)."""
    return zenoh.handlers.Callback(callback, indirect=False)


def ask(session: zenoh.Session, key_expr: str, payload: bytes | None, timeout: float
        ) -> list[zenoh.Reply]:
    """The replies to a query, asked again while it meets no one, until ``timeout`` (s).

    A session that asks before it knows of the queryable (a new session: its peers'
    declarations still on their way) meets no one, and Zenoh answers at once with no reply:
    a client made and used at once (docs/controllers.md's) said "no controller answered
    within 5 s" after a fraction of a second. A query some queryable got is not asked again:
    its replies, or the whole timeout, end the wait."""
    deadline = time.monotonic() + timeout
    while True:
        replies = list(session.get(key_expr, payload=payload,
                                   timeout=max(deadline - time.monotonic(), MIN_WAIT)))
        if replies or time.monotonic() + ASK_AGAIN >= deadline:
            return replies
        time.sleep(ASK_AGAIN)
