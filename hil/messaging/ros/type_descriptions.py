"""A node's ``~/get_type_description`` service (type_description_interfaces, REP-2016):
the description of every type the node's endpoints use, which ROS tools that meet a type
they were not built with (``ros2 topic echo`` through dynamic type support) ask for."""

from __future__ import annotations

from hil.messaging import cdr
from hil.messaging.ros.interfaces import TypeHashes, distro_types, service_part
from hil.messaging.ros.node import RosNode, ServiceRequest

SERVICE = "type_description_interfaces/srv/GetTypeDescription"


class TypeDescriptionService:
    """Answers for the types of ``node``'s endpoints (``node.interfaces``, read at each
    request: endpoints declared later are described too)."""

    def __init__(self, node: RosNode, hashes: TypeHashes):
        self._node, self._hashes = node, hashes
        self._types = distro_types(hashes.distro)
        self._service = node.service(
            f"{node.namespace.rstrip('/')}/{node.name}/get_type_description",
            hashes.service(SERVICE), self._on_request)

    def _on_request(self, request: ServiceRequest) -> None:
        try:
            asked = cdr.decode(request.payload, service_part(f"{SERVICE}_Request"), self._types)
        except ValueError as exc:
            request.reply_error(str(exc))
            return
        interface = self._node.interfaces.get(asked.type_name)
        problem = ""
        if interface is None:
            problem = (f"this node uses no type '{asked.type_name}'; it uses: "
                       f"{', '.join(sorted(self._node.interfaces))}")
        elif asked.type_hash and asked.type_hash != interface.type_hash:
            problem = (f"'{asked.type_name}' is {interface.type_hash} here, not "
                       f"{asked.type_hash} (another ROS 2 distribution's definition?)")
        described = (self._description(asked.type_name) if not problem else
                     self._message("TypeDescription", type_description=self._individual(
                         {"type_name": "", "fields": []}), referenced_type_descriptions=[]))
        # hil keeps no .msg sources: type_sources stays empty, as rcl answers without them
        request.reply(cdr.encode(self._types.types[service_part(f"{SERVICE}_Response")](
            successful=not problem, failure_reason=problem, type_description=described,
            type_sources=[], extra_information=[]), self._types))

    def _description(self, name: str):
        document = self._hashes.description(name)
        return self._message(
            "TypeDescription", type_description=self._individual(document["type_description"]),
            referenced_type_descriptions=[self._individual(d) for d in
                                          document["referenced_type_descriptions"]])

    def _individual(self, description: dict):
        fields = [self._message("Field", name=field["name"], default_value="",
                                type=self._message("FieldType", **field["type"]))
                  for field in description["fields"]]
        return self._message("IndividualTypeDescription", type_name=description["type_name"],
                             fields=fields)

    def _message(self, kind: str, **fields):
        return self._types.types[f"type_description_interfaces/msg/{kind}"](**fields)

    def close(self) -> None:
        self._service.close()
