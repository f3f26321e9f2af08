"""A ROS 2 node's parameters, served as rclcpp serves them: ``~/list_parameters``,
``~/get_parameters``, ``~/get_parameter_types``, ``~/describe_parameters``,
``~/set_parameters``, ``~/set_parameters_atomically`` (rcl_interfaces), and each declaration
and change published on ``/parameter_events``.

A parameter is read-only unless declared settable; the server's ``apply`` takes every change
of one request at once (a set of several is atomic) and applies them all or refuses them
with a ValueError, whose text is the answer's reason. Values keep their declared type (no
dynamic typing), as rclcpp's default.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from hil.messaging import cdr
from hil.messaging.ros.interfaces import TypeHashes, distro_types, service_part
from hil.messaging.ros.node import RosNode, ServiceRequest
from hil.messaging.ros.rmw_zenoh import QoS

#: rmw_qos_profile_parameter_events: reliable, volatile, keep last 1000
PARAMETER_EVENTS_QOS = QoS(depth=1000)
#: rcl_interfaces/msg/ParameterType by the Python type of a value (lists: of that type)
_SCALAR_TYPES = {bool: 1, int: 2, float: 3, str: 4}
_ARRAY_TYPES = {bool: 6, int: 7, float: 8, str: 9}
TYPE_NAMES = {0: "not set", 1: "bool", 2: "integer", 3: "double", 4: "string",
              5: "byte array", 6: "bool array", 7: "integer array", 8: "double array",
              9: "string array"}

Value = bool | int | float | str | tuple


@dataclass
class Parameter:
    """One declared parameter; a read-only one says why in ``read_only_reason``."""

    name: str
    value: Value
    description: str
    settable: bool = False
    read_only_reason: str = "fixed for the process' life"

    @property
    def type(self) -> int:
        return type_of(self.value)


def type_of(value: Value) -> int:
    """The ParameterType of a Python value (a tuple: an array of its first item's type)."""
    if isinstance(value, tuple):
        return _ARRAY_TYPES[type(value[0])] if value else _ARRAY_TYPES[str]
    return _SCALAR_TYPES[type(value)]


class ParameterServer:
    """The parameter services of ``node`` over ``parameters``, and /parameter_events
    (stamped on ``ros_time``, the node's ROS time, as rclcpp stamps them).
    ``apply(changes)``: takes {name: new value} of settable parameters, all or none
    (ValueError: none, with why)."""

    def __init__(self, node: RosNode, hashes: TypeHashes, parameters: list[Parameter],
                 apply: Callable[[dict[str, Value]], None] | None = None,
                 ros_time: Callable[[], float] = time.time):
        self._node, self._apply_changes, self._ros_time = node, apply, ros_time
        self._types = distro_types(hashes.distro)
        self._parameters = {p.name: p for p in parameters}
        self._lock = threading.Lock()
        base = f"{node.namespace.rstrip('/')}/{node.name}"
        handlers = {"list_parameters": ("ListParameters", self._on_list),
                    "get_parameters": ("GetParameters", self._on_get),
                    "get_parameter_types": ("GetParameterTypes", self._on_types),
                    "describe_parameters": ("DescribeParameters", self._on_describe),
                    "set_parameters": ("SetParameters", self._on_set),
                    "set_parameters_atomically": ("SetParametersAtomically", self._on_set_all)}
        self._services = [
            node.service(f"{base}/{name}", hashes.service(f"rcl_interfaces/srv/{kind}"),
                         self._answering(kind, handler))
            for name, (kind, handler) in handlers.items()]
        self._events = node.publisher("/parameter_events",
                                      hashes.message("rcl_interfaces/msg/ParameterEvent"),
                                      PARAMETER_EVENTS_QOS)
        self._publish_event(new=list(self._parameters.values()))

    def close(self) -> None:
        for service in self._services:
            service.close()

    # --- the services ---------------------------------------------------------------

    def _answering(self, kind: str, handler: Callable) -> Callable[[ServiceRequest], None]:
        """A service handler: decodes the request, answers what ``handler`` returns (the
        response's fields), or an error reply naming what was malformed."""
        request_type = service_part(f"rcl_interfaces/srv/{kind}_Request")
        response_type = service_part(f"rcl_interfaces/srv/{kind}_Response")

        def answer(request: ServiceRequest) -> None:
            try:
                decoded = cdr.decode(request.payload, request_type, self._types)
            except ValueError as exc:
                request.reply_error(str(exc))
                return
            response = self._types.types[response_type](**handler(decoded))
            request.reply(cdr.encode(response, self._types))
        return answer

    def _on_list(self, request) -> dict:
        prefixes, depth = list(request.prefixes), int(request.depth)
        with self._lock:
            names = [name for name in self._parameters
                     if _listed(name, prefixes, depth)]
        groups = sorted({name.rpartition(".")[0] for name in names if "." in name})
        return {"result": self._types.types["rcl_interfaces/msg/ListParametersResult"](
            names=names, prefixes=groups)}

    def _on_get(self, request) -> dict:
        with self._lock:
            return {"values": [self._value_msg(self._parameters[n].value)
                               if n in self._parameters else self._value_msg(None)
                               for n in request.names]}

    def _on_types(self, request) -> dict:
        with self._lock:
            return {"types": np.array([self._parameters[n].type if n in self._parameters
                                       else 0 for n in request.names], dtype=np.uint8)}

    def _on_describe(self, request) -> dict:
        descriptor = self._types.types["rcl_interfaces/msg/ParameterDescriptor"]
        described = []
        with self._lock:
            for name in request.names:
                parameter = self._parameters.get(name)
                described.append(descriptor(
                    name=name, type=parameter.type if parameter else 0,
                    description=parameter.description if parameter else "not declared",
                    additional_constraints="" if parameter is None or parameter.settable else
                    f"read-only: {parameter.read_only_reason}",
                    read_only=parameter is None or not parameter.settable,
                    dynamic_typing=False, floating_point_range=[], integer_range=[]))
        return {"descriptors": described}

    def _on_set(self, request) -> dict:
        return {"results": [self._result(*self._apply([wanted]))
                            for wanted in request.parameters]}

    def _on_set_all(self, request) -> dict:
        return {"result": self._result(*self._apply(list(request.parameters)))}

    # --- setting ----------------------------------------------------------------------

    def _apply(self, wanted: list) -> tuple[bool, str]:
        """Set every one of ``wanted`` (rcl_interfaces Parameters) or none: (done, why not)."""
        with self._lock:
            changes = []
            for item in wanted:
                parameter = self._parameters.get(item.name)
                problem = self._refusal(parameter, item)
                if problem:
                    return False, problem
                changes.append((parameter, _python_value(item.value)))
            try:
                self._apply_changes({parameter.name: value for parameter, value in changes})
            except ValueError as exc:
                return False, str(exc)
            for parameter, value in changes:
                parameter.value = value
        self._publish_event(changed=[parameter for parameter, _ in changes])
        return True, ""

    @staticmethod
    def _refusal(parameter: Parameter | None, item) -> str:
        if parameter is None:
            return f"parameter '{item.name}' is not declared"
        if not parameter.settable:
            return f"parameter '{item.name}' is read-only: {parameter.read_only_reason}"
        if item.value.type != parameter.type:
            return (f"parameter '{item.name}' is a {TYPE_NAMES[parameter.type]}, not a "
                    f"{TYPE_NAMES.get(item.value.type, str(item.value.type))}")
        return ""

    def _result(self, successful: bool, reason: str):
        return self._types.types["rcl_interfaces/msg/SetParametersResult"](
            successful=successful, reason=reason)

    # --- messages ---------------------------------------------------------------------

    def _value_msg(self, value: Value | None):
        fields = {"type": 0 if value is None else type_of(value), "bool_value": False,
                  "integer_value": 0, "double_value": 0.0, "string_value": "",
                  "byte_array_value": np.zeros(0, np.uint8),
                  "bool_array_value": np.zeros(0, bool),
                  "integer_array_value": np.zeros(0, np.int64),
                  "double_array_value": np.zeros(0), "string_array_value": []}
        if value is not None:
            field = _FIELDS[fields["type"]]
            fields[field] = (list(value) if field == "string_array_value"
                             else np.array(value, dtype=_ARRAY_DTYPES[field])
                             if isinstance(value, tuple) else value)
        return self._types.types["rcl_interfaces/msg/ParameterValue"](**fields)

    def _publish_event(self, new: list[Parameter] = (), changed: list[Parameter] = ()) -> None:
        parameter = self._types.types["rcl_interfaces/msg/Parameter"]
        event = self._types.types["rcl_interfaces/msg/ParameterEvent"](
            stamp=cdr.time_msg(self._ros_time()),
            node=f"{self._node.namespace.rstrip('/')}/{self._node.name}",
            new_parameters=[parameter(name=p.name, value=self._value_msg(p.value)) for p in new],
            changed_parameters=[parameter(name=p.name, value=self._value_msg(p.value))
                                for p in changed],
            deleted_parameters=[])
        self._events.put(cdr.encode(event, self._types))


#: the ParameterValue field of each ParameterType, and the dtype of the numeric arrays
_FIELDS = {1: "bool_value", 2: "integer_value", 3: "double_value", 4: "string_value",
           6: "bool_array_value", 7: "integer_array_value", 8: "double_array_value",
           9: "string_array_value"}
_ARRAY_DTYPES = {"bool_array_value": bool, "integer_array_value": np.int64,
                 "double_array_value": np.float64}


def _python_value(value) -> Value:
    """A ParameterValue's value as Python (arrays as tuples)."""
    field = _FIELDS.get(value.type)
    if field is None:
        raise ValueError(f"unsupported parameter type {value.type}")
    got = getattr(value, field)
    if not field.endswith("array_value"):
        return got
    return tuple(got.tolist() if isinstance(got, np.ndarray) else got)


def _listed(name: str, prefixes: list[str], depth: int) -> bool:
    """Whether ``list_parameters`` lists ``name`` (rcl's rule: under one of ``prefixes``, or
    any name without prefixes; no deeper than ``depth`` separators below it, 0: any)."""
    if not prefixes:
        return depth == 0 or name.count(".") < depth
    for prefix in prefixes:
        if name == prefix or name.startswith(prefix + "."):
            below = name[len(prefix):].count(".")
            return depth == 0 or below <= depth
    return False
