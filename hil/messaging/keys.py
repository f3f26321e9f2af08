"""hil's Zenoh key expressions, all under ``hil/<robot>/``:

=====================================================  ==========================================
``joint_states``                                       publication, sensor_msgs/JointState
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

from collections.abc import Callable

import zenoh

#: the FollowJointTrajectory action's keys, under ``hil/<robot>/``
ACTION = "follow_joint_trajectory/_action"


def key(robot: str, name: str) -> str:
    """The key expression of ``name`` for ``robot``."""
    return f"hil/{robot}/{name}"


def direct(callback: Callable[[zenoh.Sample], None]) -> zenoh.handlers.Callback:
    """A Zenoh callback run in Zenoh's receiving thread (for short callbacks only)."""
    return zenoh.handlers.Callback(callback, indirect=False)
