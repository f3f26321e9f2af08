"""A user's ``flat_endpoints.json`` (ODrive's endpoint list for one firmware release), read
as data, and the device descriptor JSON a simulated ODrive serves from it over CAN.

The file's form is the one ODrive's own CAN example reads (ODriveResources
``examples/can_param_access.py``): ``fw_version`` ("0.6.11", a "-suffix" allowed) and
``hw_version`` ("4.4.58"), which that example checks against Get_Version, and
``endpoints``: ``{"axis0.controller.input_pos": {"id": 383, "type": "float", ...}}``, a
function with ``inputs`` and ``outputs`` lists of ``{"name", "type"}``. The file is never
executed; a bad one is refused with a message naming it.

The descriptor is the nested form the maker's ``odrive`` library flattens
(``odrive/runtime_device.py``, ``_flatten_json``: objects with ``members``, leaves with
``id``, ``type``, ``access``), and its id is Fibre's: the CRC-16 (polynomial 0x3D65, seeded
with the protocol version 1) of the JSON in the upper half, that CRC's own CRC-16 of the
JSON in the lower half (ODrive's open fibre ``legacy_protocol``); the ``odrive`` library
keeps ``json_id >> 16`` as the JSON's CRC (``odrive/_json_cache.py``). libodrive 0.9.6 does
not check the CRC against the JSON it reads over CAN (recorded: a wrong id was taken); it
keys its descriptor cache (``$XDG_CACHE_HOME/odrivetool/device_json/<id>.json``) by the id,
so the id follows hil's descriptor: a changed file gets a new id, and hil's descriptor
(which differs from the firmware's own) never shares a cached real ODrive's. Keys of the
file other than those above are not read.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

from hil.errors import HilError
from hil.input_files import read_input_file, refusal_text

#: the value types of endpoints and their little-endian layouts (ODrive's CAN example's
#: ``format_lookup``, the ``odrive`` library's ``codecs``)
FORMATS = {"bool": "?", "uint8": "B", "int8": "b", "uint16": "H", "int16": "h",
           "uint32": "I", "int32": "i", "uint64": "Q", "int64": "q", "float": "f",
           "endpoint_ref": "I"}
FUNCTION = "function"
CRC16_POLYNOMIAL = 0x3D65      # fibre's CANONICAL_CRC16_POLYNOMIAL
FIBRE_PROTOCOL_VERSION = 1     # the CRC's seed


@dataclass(frozen=True)
class Endpoint:
    """One endpoint: its id, its type, and a function's argument and result types."""

    path: str
    id: int
    type: str
    access: str = "rw"
    inputs: tuple[tuple[str, str], ...] = ()
    outputs: tuple[tuple[str, str], ...] = ()

    @property
    def format(self) -> str:
        """The struct layout of its value (a function's: of its inputs)."""
        types = [t for _, t in self.inputs] if self.type == FUNCTION else [self.type]
        return "<" + "".join(FORMATS[t] for t in types)

    def describe(self) -> dict:
        if self.type == FUNCTION:
            return {"name": self.path.rsplit(".", 1)[-1], "id": self.id, "type": FUNCTION,
                    "inputs": [{"name": n, "type": t} for n, t in self.inputs],
                    "outputs": [{"name": n, "type": t} for n, t in self.outputs]}
        return {"name": self.path.rsplit(".", 1)[-1], "id": self.id, "type": self.type,
                "access": self.access}


@dataclass(frozen=True)
class EndpointFile:
    """A flat_endpoints.json read and checked; ``by_path`` and ``by_id`` index it."""

    path: Path
    fw_version: tuple[int, int, int]
    hw_version: tuple[int, int, int]
    by_path: dict[str, Endpoint]

    @property
    def by_id(self) -> dict[int, Endpoint]:
        return {e.id: e for e in self.by_path.values()}

    def descriptor(self) -> bytes:
        """The device JSON (nested objects, compact), as endpoint 0 serves it."""
        root: list[dict] = []
        for endpoint in self.by_path.values():
            level = root
            for name in endpoint.path.split(".")[:-1]:
                member = next((m for m in level if m["name"] == name), None)
                if member is None:
                    member = {"name": name, "type": "object", "members": []}
                    level.append(member)
                level = member["members"]
            level.append(endpoint.describe())
        return json.dumps(root, separators=(",", ":")).encode()


def crc16(seed: int, data: bytes) -> int:
    """Fibre's CRC-16: MSB first, not reflected, no final XOR."""
    remainder = seed
    for byte in data:
        remainder ^= byte << 8
        for _ in range(8):
            remainder = (remainder << 1) ^ CRC16_POLYNOMIAL if remainder & 0x8000 \
                else remainder << 1
            remainder &= 0xFFFF
    return remainder


def json_id(descriptor: bytes) -> int:
    """The descriptor's version id (endpoint 0 read at offset 0xFFFFFFFF)."""
    crc = crc16(FIBRE_PROTOCOL_VERSION, descriptor)
    return crc << 16 | crc16(crc, descriptor)


def load_endpoints(path: Path) -> EndpointFile:
    """Read ``path`` as every named file is (hil/input_files.py: a regular file, bounded,
    UTF-8 as JSON is, nested no deeper than json.loads may recurse); ValueError naming the
    file and what is wrong (the bus config's reader names the drive's line)."""
    try:
        text = read_input_file(Path(path), "endpoints file", hint="", syntax="json")
    except HilError as exc:
        raise ValueError(refusal_text(exc)) from None
    try:
        data = json.loads(text)
    except json.JSONDecodeError as exc:
        raise ValueError(f"endpoints file {path}: not JSON ({exc})") from None
    if not isinstance(data, dict) or not isinstance(data.get("endpoints"), dict):
        raise ValueError(f"endpoints file {path}: no 'endpoints' mapping: give ODrive's "
                         "flat_endpoints.json of your firmware release")
    endpoints = {name: _endpoint(path, name, spec) for name, spec in data["endpoints"].items()}
    ids: dict[int, str] = {}
    for endpoint in endpoints.values():
        if endpoint.id in ids:
            raise ValueError(f"endpoints file {path}: '{endpoint.path}' and "
                             f"'{ids[endpoint.id]}' share id {endpoint.id}")
        ids[endpoint.id] = endpoint.path
    return EndpointFile(Path(path), _version(path, data, "fw_version"),
                        _version(path, data, "hw_version"), endpoints)


def _version(path: Path, data: dict, key: str) -> tuple[int, int, int]:
    """"0.6.11" or "0.6.11-dev": three numbers 0..255 (Get_Version's bytes)."""
    text = data.get(key)
    parts = str(text).partition("-")[0].split(".") if isinstance(text, str) else []
    if len(parts) != 3 or not all(p.isdigit() and int(p) < 256 for p in parts):
        raise ValueError(f"endpoints file {path}: '{key}' must be like \"0.6.11\", "
                         f"not {text!r}")
    return int(parts[0]), int(parts[1]), int(parts[2])


def _endpoint(path: Path, name: str, spec: object) -> Endpoint:
    where = f"endpoints file {path}: endpoint '{name}'"
    if not isinstance(spec, dict):
        raise ValueError(f"{where}: must be a mapping with 'id' and 'type'")
    ident, kind = spec.get("id"), spec.get("type")
    if not isinstance(ident, int) or isinstance(ident, bool) or not 1 <= ident <= 0xFFFF:
        # id 0 is the descriptor itself; the RxSdo's endpoint id is a uint16
        raise ValueError(f"{where}: 'id' must be 1..65535, not {ident!r}")
    if kind == FUNCTION:
        return Endpoint(name, ident, kind, inputs=_arguments(where, spec, "inputs"),
                        outputs=_arguments(where, spec, "outputs"))
    if kind not in FORMATS:
        raise ValueError(f"{where}: unknown type {kind!r} (one of "
                         f"{', '.join([*FORMATS, FUNCTION])})")
    access = spec.get("access", "rw")
    if not isinstance(access, str) or not set(access) <= {"r", "w"}:
        raise ValueError(f"{where}: 'access' must be 'r', 'w' or 'rw', not {access!r}")
    return Endpoint(name, ident, kind, access)


def _arguments(where: str, spec: dict, key: str) -> tuple[tuple[str, str], ...]:
    items = spec.get(key, [])
    if not isinstance(items, list) or not all(
            isinstance(i, dict) and i.get("type") in FORMATS for i in items):
        raise ValueError(f"{where}: '{key}' must be a list of {{name, type}} with types "
                         f"among {', '.join(FORMATS)}")
    return tuple((str(i.get("name", "")), i["type"]) for i in items)
