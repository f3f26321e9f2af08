"""The ROS 2 interfaces hil serves: their names in rmw_zenoh's ``dds_`` form and their
RIHS01 type hashes (REP-2016) for a ROS distribution.

hil's own definitions (:data:`hil.messaging.cdr.DEFINITIONS`) are the interfaces as ROS 2
Jazzy releases them; :data:`DISTRO_DEFINITIONS` holds what a later distribution's releases
changed, and :func:`distro_types` is the CDR codec of that distribution's layouts. A
message's hash comes from rosbags' type store for the distribution (its ``hash_rihs01``). Services and actions need what rosidl synthesises around their
parts, which rosbags does not: the service type (``request_message``,
``response_message``, ``event_message``), its ``_Event`` message (``service_msgs/
ServiceEventInfo`` plus a request and a response bounded to one), and an action's
``_SendGoal``/``_GetResult`` services and ``_FeedbackMessage``. Those are hashed here
over the same JSON form rosbags and rosidl hash (the type, then its referenced types
sorted by name), with ``char`` as rosidl maps it (``uint8``).
"""

from __future__ import annotations

import functools
import hashlib
import json
from dataclasses import dataclass

from rosbags.typesys import Stores, get_types_from_msg, get_typestore
from rosbags.typesys.base import Nodetype

from hil.messaging import cdr

#: ROS 2 distributions with rmw_zenoh and type hashes, and rosbags' store of each
DISTROS = {"jazzy": Stores.ROS2_JAZZY, "kilted": Stores.ROS2_KILTED,
           "lyrical": Stores.ROS2_LYRICAL}
DEFAULT_DISTRO = "jazzy"

FEEDBACK = "control_msgs/action/FollowJointTrajectory_Feedback"
#: control_msgs 6.3 (released for Kilted and Lyrical; Jazzy's is 5.x) added to
#: FollowJointTrajectory's feedback "the currently used point" of the trajectory, after
#: ``error``, and of the multi-DOF trajectory, last. Checked: hashed, this placement alone
#: gives the FeedbackMessage hash ROS computes for Kilted (RIHS01_95618cc7...)
_FEEDBACK_WITH_INDICES = cdr.DEFINITIONS[FEEDBACK].replace(
    "trajectory_msgs/JointTrajectoryPoint error\n",
    "trajectory_msgs/JointTrajectoryPoint error\nint32 index\n") + "\nint32 multi_dof_index"
#: what each distribution's releases change in hil's own definitions (Jazzy's)
DISTRO_DEFINITIONS: dict[str, dict[str, str]] = {
    "jazzy": {},
    "kilted": {FEEDBACK: _FEEDBACK_WITH_INDICES},
    "lyrical": {FEEDBACK: _FEEDBACK_WITH_INDICES},
}

# REP-2016 field type ids (type_description_interfaces/FieldType)
_TYPE_IDS = {"int8": 2, "uint8": 3, "int16": 4, "uint16": 5, "int32": 6, "uint32": 7,
             "int64": 8, "uint64": 9, "float32": 10, "float64": 11, "float128": 12,
             "char": 3, "bool": 15, "byte": 16, "string": 17}
_NESTED, _BOUNDED_STRING = 1, 21
_ARRAY, _BOUNDED_SEQUENCE, _SEQUENCE = 48, 96, 144

# parts of interfaces hil uses that rosbags' stores lack, as .msg text
_EXTRA_DEFINITIONS = {
    "service_msgs/msg/ServiceEventInfo":
        "uint8 event_type\nbuiltin_interfaces/msg/Time stamp\nuint8[16] client_gid\n"
        "int64 sequence_number",
    "action_msgs/srv/CancelGoal_Request": "action_msgs/msg/GoalInfo goal_info",
    "action_msgs/srv/CancelGoal_Response":
        "int8 return_code\naction_msgs/msg/GoalInfo[] goals_canceling",
    "std_srvs/srv/Trigger_Request": "",
    "controller_manager_msgs/srv/ListControllers_Request": "",
    "std_srvs/srv/Trigger_Response": "bool success\nstring message",
    # a node's parameter services (rcl_interfaces) and type description service
    "rcl_interfaces/srv/ListParameters_Request": "string[] prefixes\nuint64 depth",
    "rcl_interfaces/srv/ListParameters_Response": "rcl_interfaces/msg/ListParametersResult result",
    "rcl_interfaces/srv/GetParameters_Request": "string[] names",
    "rcl_interfaces/srv/GetParameters_Response": "rcl_interfaces/msg/ParameterValue[] values",
    "rcl_interfaces/srv/GetParameterTypes_Request": "string[] names",
    "rcl_interfaces/srv/GetParameterTypes_Response": "uint8[] types",
    "rcl_interfaces/srv/DescribeParameters_Request": "string[] names",
    "rcl_interfaces/srv/DescribeParameters_Response":
        "rcl_interfaces/msg/ParameterDescriptor[] descriptors",
    "rcl_interfaces/srv/SetParameters_Request": "rcl_interfaces/msg/Parameter[] parameters",
    "rcl_interfaces/srv/SetParameters_Response": "rcl_interfaces/msg/SetParametersResult[] results",
    "rcl_interfaces/srv/SetParametersAtomically_Request":
        "rcl_interfaces/msg/Parameter[] parameters",
    "rcl_interfaces/srv/SetParametersAtomically_Response":
        "rcl_interfaces/msg/SetParametersResult result",
    "type_description_interfaces/srv/GetTypeDescription_Request":
        "string type_name\nstring type_hash\nbool include_type_sources",
    "type_description_interfaces/srv/GetTypeDescription_Response":
        "bool successful\nstring failure_reason\n"
        "type_description_interfaces/msg/TypeDescription type_description\n"
        "type_description_interfaces/msg/TypeSource[] type_sources\n"
        "type_description_interfaces/msg/KeyValue[] extra_information",
}


@dataclass(frozen=True)
class Interface:
    """A ROS 2 message or service type as rmw_zenoh keys it."""

    name: str          # e.g. sensor_msgs/msg/JointState
    type_name: str     # e.g. sensor_msgs::msg::dds_::JointState_
    type_hash: str     # RIHS01_...


def known_distro(distro: str) -> str:
    """``distro`` if hil has its type hashes; else a ValueError naming the known ones."""
    if distro not in DISTROS:
        raise ValueError(f"unknown ROS 2 distribution {distro!r}; hil knows "
                         f"{', '.join(sorted(DISTROS))}")
    return distro


def dds_type_name(name: str) -> str:
    """``pkg/msg/Name`` -> ``pkg::msg::dds_::Name_`` (what rmw_zenoh's type support names)."""
    package, kind, base = name.split("/")
    return f"{package}::{kind}::dds_::{base}_"


@functools.cache
def distro_types(distro: str):
    """The CDR codec (a rosbags type store) of the interfaces hil's ROS faces use, laid out
    as ``distro`` releases them: the distribution's own messages, hil's definitions with
    what the distribution changed, the service parts rosbags leaves out (filed, as rosbags
    files them, under ``pkg/srv/msg/X_Request``)."""
    store = get_typestore(DISTROS[known_distro(distro)])
    for name, text in {**cdr.DEFINITIONS, **DISTRO_DEFINITIONS[distro],
                       **_EXTRA_DEFINITIONS}.items():
        if name not in store.fielddefs:
            store.register(get_types_from_msg(text, name))
    return store


def service_part(name: str) -> str:
    """A service part's name in :func:`distro_types`: ``pkg/srv/X_Request`` ->
    ``pkg/srv/msg/X_Request``."""
    return name.replace("/srv/", "/srv/msg/")


class TypeHashes:
    """RIHS01 hashes of the interfaces of one ROS 2 distribution."""

    def __init__(self, distro: str = DEFAULT_DISTRO):
        self.distro = known_distro(distro)
        self._store = get_typestore(DISTROS[distro])
        self._fields: dict[str, list] = {}
        for name, text in {**cdr.DEFINITIONS, **DISTRO_DEFINITIONS[distro],
                           **_EXTRA_DEFINITIONS}.items():
            self.define(name, text)

    def define(self, name: str, text: str) -> None:
        """Add a type (``pkg/msg/X``, ``pkg/srv/X_Request``...) from its .msg text, under
        exactly ``name``: rosbags files a service's or action's parts under
        ``pkg/srv/msg/...``, which would change the hash."""
        (_, fields), = get_types_from_msg(text, "hil_hashing/msg/Scratch").values()
        self._fields[name] = [(field, _renamed(desc)) for field, desc in fields]

    def _fields_of(self, name: str) -> list:
        if name in self._fields:
            return self._fields[name]
        if name not in self._store.fielddefs:
            raise KeyError(f"no definition of {name} for ROS 2 {self.distro}")
        return self._store.fielddefs[name][1]

    def _description(self, name: str) -> dict:
        fields = self._fields_of(name) or [
            ("structure_needs_at_least_one_member", (Nodetype.BASE, ("uint8", 0)))]
        return {"type_name": name, "fields": [_field(field, desc) for field, desc in fields]}

    def _closure(self, name: str, found: dict[str, dict]) -> dict[str, dict]:
        for field in self._description(name)["fields"]:
            nested = field["type"]["nested_type_name"]
            if nested and nested not in found:
                found[nested] = self._description(nested)
                self._closure(nested, found)
        return found

    def description(self, name: str) -> dict:
        """REP-2016's TypeDescription of a type: its fields and every type it refers to,
        sorted by name (type_description_interfaces' layout, as dicts)."""
        referenced = self._closure(name, {})
        return {"type_description": self._description(name),
                "referenced_type_descriptions": [referenced[k] for k in sorted(referenced)]}

    @functools.cache
    def rihs01(self, name: str) -> str:
        """The RIHS01 hash of a message type (or of a type defined here)."""
        document = self.description(name)
        return "RIHS01_" + hashlib.sha256(json.dumps(document).encode()).hexdigest()

    def message(self, name: str) -> Interface:
        return Interface(name, dds_type_name(name), self.rihs01(name))

    def service(self, name: str, request: str | None = None,
                response: str | None = None) -> Interface:
        """A service type ``pkg/srv/Name`` (or an action's ``pkg/action/Name_SendGoal``)
        whose parts are ``name + "_Request"`` and ``"_Response"`` (or those given)."""
        request, response = request or f"{name}_Request", response or f"{name}_Response"
        event = f"{name}_Event"
        self.define(event, f"service_msgs/msg/ServiceEventInfo info\n{request}[<=1] request\n"
                            f"{response}[<=1] response")
        self.define(name, f"{request} request_message\n{response} response_message\n"
                           f"{event} event_message")
        return Interface(name, dds_type_name(name), self.rihs01(name))


def _renamed(desc):
    """A parsed field's type with rosbags' ``pkg/srv/msg/X`` names back to ``pkg/srv/X``."""
    if isinstance(desc, tuple):
        return tuple(_renamed(part) for part in desc)
    if isinstance(desc, str):
        return desc.replace("/srv/msg/", "/srv/").replace("/action/msg/", "/action/")
    return desc


def _field(name: str, desc) -> dict:
    """One FieldDescription of REP-2016 from a rosbags field type."""
    offset = capacity = string_capacity = 0
    nested = ""
    if desc[0] == Nodetype.ARRAY:
        offset, capacity = _ARRAY, desc[1][1]
        kind, rest = desc[1][0]
    elif desc[0] == Nodetype.SEQUENCE:
        capacity = desc[1][1]
        offset = _BOUNDED_SEQUENCE if capacity else _SEQUENCE
        kind, rest = desc[1][0]
    else:
        kind, rest = desc
    if kind == Nodetype.NAME:
        type_id, nested = offset + _NESTED, rest
    elif rest[0] == "string" and rest[1]:
        type_id, string_capacity = offset + _BOUNDED_STRING, rest[1]
    else:
        type_id = offset + _TYPE_IDS[rest[0]]
    return {"name": name, "type": {"type_id": type_id, "capacity": capacity,
                                   "string_capacity": string_capacity,
                                   "nested_type_name": nested}}


@dataclass(frozen=True)
class FollowJointTrajectory:
    """The interfaces of control_msgs/action/FollowJointTrajectory's five endpoints."""

    send_goal: Interface
    cancel_goal: Interface
    get_result: Interface
    feedback: Interface
    status: Interface
    distro: str                      # whose layouts the payloads have (distro_types)

    @classmethod
    def for_distro(cls, hashes: TypeHashes) -> FollowJointTrajectory:
        base = "control_msgs/action/FollowJointTrajectory"
        return cls(hashes.service(f"{base}_SendGoal"),
                   hashes.service("action_msgs/srv/CancelGoal"),
                   hashes.service(f"{base}_GetResult"),
                   hashes.message(f"{base}_FeedbackMessage"),
                   hashes.message("action_msgs/msg/GoalStatusArray"), hashes.distro)


__all__ = ["DEFAULT_DISTRO", "DISTROS", "DISTRO_DEFINITIONS", "FollowJointTrajectory",
           "Interface", "TypeHashes", "dds_type_name", "distro_types", "known_distro", "service_part"]
