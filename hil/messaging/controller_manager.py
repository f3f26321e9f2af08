"""The controller manager on Zenoh (keys under ``hil/<robot>/``), CDR of
controller_manager_msgs as ros2_control's jazzy branch defines them:

====================================================  ==========================================
``controller_manager/list_controllers``               query -> ListControllers_Response
``controller_manager/switch_controller``              query: SwitchController_Request ->
                                                      SwitchController_Response (ok, message)
``<controller>/commands``                             query: std_msgs/Float64MultiArray, a
                                                      forward command controller's command;
                                                      an empty reply takes it, an error reply
                                                      says why it was refused
====================================================  ==========================================

The commands are queries, not puts, so that the access policy (hil.zenoh_security) lets an
operator command controllers without any put right (no key of a CAN frame can be reached),
and a refused command is answered with why. A streaming client need not wait for the
answers (:meth:`ControllerManagerClient.command`)."""

from __future__ import annotations

import numpy as np
import zenoh

from hil.controllers.manager import ControllerInfo, ControllerManager, Strictness
from hil.messaging import cdr
from hil.messaging.keys import ask, key
from hil.realtime import enter_side_work

LIST = "controller_manager/list_controllers"
SWITCH = "controller_manager/switch_controller"


def commands_key(robot: str, controller: str) -> str:
    return key(robot, f"{controller}/commands")


def strictness_of(value: int) -> Strictness:
    """A request's strictness: 0 takes controller_manager's default (its parameter
    defaults.switch_controller.strictness, "strict"); 3 and 4 (AUTO, FORCE_AUTO, for
    chained controllers, which hil has none of) are BEST_EFFORT, as switch_controller_cb
    defaults them. Another value, which SwitchController does not define, is taken as
    BEST_EFFORT too (hil's choice: controller_manager passes it on to checks that test
    for STRICT and BEST_EFFORT only)."""
    if value in (0, Strictness.STRICT):
        return Strictness.STRICT
    return Strictness.BEST_EFFORT


def controller_state_msg(info: ControllerInfo, update_rate: int):
    return cdr.msg(cdr.CONTROLLER_STATE, name=info.name, state=info.state, type=info.type,
                   is_async=False, update_rate=update_rate,
                   claimed_interfaces=list(info.claimed_interfaces),
                   required_command_interfaces=list(info.required_command_interfaces),
                   required_state_interfaces=list(info.required_state_interfaces),
                   is_chainable=False, is_chained=False, exported_state_interfaces=[],
                   reference_interfaces=[], chain_connections=[])


def list_response(manager: ControllerManager) -> bytes:
    """ListControllers_Response of ``manager``'s controllers (each updated every cycle), CDR."""
    update_rate = min(65535, round(1.0 / manager.period))      # a uint16 in the message
    return cdr.encode(cdr.msg(cdr.LIST_CONTROLLERS_RESPONSE, controller=[
        controller_state_msg(info, update_rate) for info in manager.list()]))


def switch_response(manager: ControllerManager, request: bytes) -> bytes:
    """Switch as a SwitchController_Request (CDR) asks; its response, CDR. ValueError for a
    malformed request."""
    message = cdr.decode(request, cdr.SWITCH_CONTROLLER_REQUEST)
    result = manager.switch(list(message.activate_controllers),
                            list(message.deactivate_controllers),
                            strictness_of(message.strictness))
    return cdr.encode(cdr.msg(cdr.SWITCH_CONTROLLER_RESPONSE, ok=result.ok,
                              message=result.message))


def forward_command(manager: ControllerManager, name: str, payload: bytes) -> None:
    """Give the forward controller ``name`` a std_msgs/Float64MultiArray command (CDR);
    ValueError with why where it is not active or refuses it (the command is dropped)."""
    if not manager.is_active(name):
        raise ValueError(f"{name} is not active: switch to it first "
                         "(controller_manager/switch_controller); the command is dropped")
    manager.forward(name).command(cdr.decode(payload, cdr.FLOAT64_MULTI_ARRAY).data)


class ControllerManagerServer:
    """Serves a ControllerManager's list, switch and forward commands on Zenoh."""

    def __init__(self, session: zenoh.Session, robot: str, manager: ControllerManager):
        self.manager = manager
        self._queryables = [
            session.declare_queryable(key(robot, LIST), self._on_list),
            session.declare_queryable(key(robot, SWITCH), self._on_switch),
            *(session.declare_queryable(commands_key(robot, name),
                                        lambda query, name=name: self._on_command(query, name))
              for name in manager.forward_names())]

    def _on_list(self, query: zenoh.Query) -> None:
        enter_side_work()
        query.reply(query.key_expr, list_response(self.manager))

    def _on_switch(self, query: zenoh.Query) -> None:
        enter_side_work()
        try:
            query.reply(query.key_expr, switch_response(self.manager, _payload(query)))
        except ValueError as exc:
            query.reply_err(str(exc))

    def _on_command(self, query: zenoh.Query, name: str) -> None:
        try:
            forward_command(self.manager, name, _payload(query))
        except ValueError as exc:
            query.reply_err(str(exc))
            return
        query.reply(query.key_expr, b"")

    def close(self) -> None:
        for queryable in self._queryables:
            queryable.undeclare()


def _payload(query: zenoh.Query) -> bytes:
    if query.payload is None:
        raise ValueError("the query carries no payload")
    return query.payload.to_bytes()


class ControllerManagerClient:
    """The controller manager of a robot's controller process, from any process."""

    def __init__(self, session: zenoh.Session, robot: str, timeout: float = 5.0):
        self.session, self.robot, self.timeout = session, robot, timeout

    def _query(self, name: str, payload: bytes | None = None) -> bytes:
        for reply in ask(self.session, key(self.robot, name), payload, self.timeout):
            if reply.ok is not None:
                return reply.ok.payload.to_bytes()
            raise ValueError(reply.err.payload.to_string())
        raise TimeoutError(f"no controller of {self.robot} answered {name} within "
                           f"{self.timeout:g} s (is hil control running?)")

    def list(self) -> list:
        """controller_manager_msgs/ControllerState of each controller."""
        return list(cdr.decode(self._query(LIST), cdr.LIST_CONTROLLERS_RESPONSE).controller)

    def switch(self, activate=(), deactivate=(), strictness: int = Strictness.STRICT
               ) -> tuple[bool, str]:
        """(ok, message) of a switch_controller request."""
        request = cdr.msg(cdr.SWITCH_CONTROLLER_REQUEST, activate_controllers=list(activate),
                          deactivate_controllers=list(deactivate), strictness=int(strictness),
                          activate_asap=False, timeout=cdr.duration_msg(0.0))
        response = cdr.decode(self._query(SWITCH, cdr.encode(request)),
                              cdr.SWITCH_CONTROLLER_RESPONSE)
        return response.ok, response.message

    def command(self, controller: str, values, wait: bool = False) -> None:
        """Send a forward command controller its command; with ``wait``, raise ValueError
        with the controller's reason where it refused it (else fire and forget)."""
        payload = cdr.encode(cdr.msg(cdr.FLOAT64_MULTI_ARRAY, layout=cdr.msg(
            "std_msgs/msg/MultiArrayLayout", dim=[], data_offset=0),
            data=np.asarray(values, dtype=np.float64)))
        if wait:
            self._query(f"{controller}/commands", payload)
        else:
            self.session.get(commands_key(self.robot, controller), payload=payload,
                             handler=zenoh.handlers.Callback(_ignore, indirect=False),
                             timeout=self.timeout)


def _ignore(reply: zenoh.Reply) -> None:
    """A fire-and-forget command's answer, not waited for."""
