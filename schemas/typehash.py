"""RIHS01 type hashes (REP-2011), as ``rosidl_generator_type_description`` computes them.

The hash is the SHA-256 of a JSON type description built from the IDL form of the type:
``.msg`` ``char`` becomes ``uint8`` (rosidl_adapter maps it so), constants are not fields, a
message without fields has the member ``structure_needs_at_least_one_member: uint8``, and a
service ``pkg/srv/Name`` is a struct of ``request_message``, ``response_message`` and
``event_message`` (``Name_Event``: ``info: service_msgs/msg/ServiceEventInfo``,
``request: Name_Request[<=1]``, ``response: Name_Response[<=1]``); an action's services
``pkg/action/Name_SendGoal`` and ``Name_GetResult`` are built the same way. Humble has no type hashes:
its rmw_zenoh uses the literal ``TypeHashNotSupported``.
"""

from __future__ import annotations

import json
from hashlib import sha256
from typing import TYPE_CHECKING, Any

from rosbags.interfaces import Nodetype

from fleetlink.schemas.errors import TypeDefinitionError, UnknownTypeError
from fleetlink.schemas.typestore import EMPTY_MEMBER, Distro

if TYPE_CHECKING:
    from rosbags.interfaces.typing import Fielddefs, FieldDesc
    from rosbags.typesys.store import Typestore

HUMBLE_HASH = "TypeHashNotSupported"

# type_description_interfaces/msg/FieldType ids of the IDL types the .msg types map to.
_TYPE_IDS: dict[str, int] = {
    "int8": 2,
    "uint8": 3,
    "int16": 4,
    "uint16": 5,
    "int32": 6,
    "uint32": 7,
    "int64": 8,
    "uint64": 9,
    "float32": 10,
    "float64": 11,
    "float128": 12,
    "char": 3,  # .msg char is uint8 in IDL (not FieldType CHAR = 13)
    "wchar": 14,
    "bool": 15,
    "byte": 16,
    "string": 17,
    "wstring": 18,
}
_NESTED = 1
_BOUNDED_STRING = 21
_BOUNDED_WSTRING = 22
_ARRAY, _BOUNDED_SEQUENCE, _UNBOUNDED_SEQUENCE = 48, 96, 144

_SERVICE_EVENT_INFO = "service_msgs/msg/ServiceEventInfo"


def type_hash(ts: Typestore, typename: str, distro: Distro) -> str:
    """``RIHS01_<sha256 hex>`` of a message or service type; ``TypeHashNotSupported`` on Humble."""
    description = type_description(ts, typename)
    if distro == "humble":
        return HUMBLE_HASH
    text = json.dumps(description)  # Python's default separators, as rosidl uses
    return f"RIHS01_{sha256(text.encode()).hexdigest()}"


def type_description(ts: Typestore, typename: str) -> dict[str, Any]:
    """The ``TypeDescription`` (without default values) whose JSON text is hashed."""
    structs: dict[str, dict[str, Any]] = {}
    pending: list[tuple[str, str | None]] = [(typename, None)]
    while pending:
        name, parent = pending.pop()
        if name in structs:
            continue
        fields = _fields(ts, name, parent)
        structs[name] = {
            "type_name": name,
            "fields": [_field(fname, desc, name) for fname, desc in fields],
        }
        for fname, desc in fields:
            sub = _nested(desc)
            if sub is not None:
                pending.append((_ros_name(sub), f"{name}.{fname}"))
    return {
        "type_description": structs[typename],
        "referenced_type_descriptions": [structs[k] for k in sorted(structs) if k != typename],
    }


def _fields(ts: Typestore, name: str, parent: str | None) -> Fielddefs:
    entry = ts.fielddefs.get(name) or ts.fielddefs.get(_store_name(name))
    if entry is not None:
        return entry[1] or [EMPTY_MEMBER]
    service = _service_parts(ts, name)
    if service is not None:
        return service
    raise UnknownTypeError(name, parent)


def _service_parts(ts: Typestore, name: str) -> Fielddefs | None:
    """Fields of the types rosidl synthesises for a service: ``pkg/srv/Name`` and ``Name_Event``."""
    parts = name.split("/")
    if len(parts) != 3 or parts[1] not in ("srv", "action"):
        return None
    base = name.removesuffix("_Event")
    if parts[1] == "action" and not base.endswith(("_SendGoal", "_GetResult")):
        return None  # an action's services are its SendGoal and GetResult
    request, response = f"{base}_Request", f"{base}_Response"
    for half in (request, response):
        if half not in ts.fielddefs and _store_name(half) not in ts.fielddefs:
            return None
    if name.endswith("_Event"):
        return [
            ("info", (Nodetype.NAME, _SERVICE_EVENT_INFO)),
            ("request", (Nodetype.SEQUENCE, ((Nodetype.NAME, request), 1))),
            ("response", (Nodetype.SEQUENCE, ((Nodetype.NAME, response), 1))),
        ]
    return [
        ("request_message", (Nodetype.NAME, request)),
        ("response_message", (Nodetype.NAME, response)),
        ("event_message", (Nodetype.NAME, f"{name}_Event")),
    ]


def _store_name(name: str) -> str:
    """rosbags registers service halves parsed from .msg text as ``pkg/srv/msg/Name_Request``."""
    parts = name.split("/")
    if len(parts) == 3 and parts[1] == "srv":
        return f"{parts[0]}/srv/msg/{parts[2]}"
    return name


def _ros_name(name: str) -> str:
    return name.replace("/srv/msg/", "/srv/")


def _nested(desc: FieldDesc) -> str | None:
    if desc[0] == Nodetype.NAME:
        return desc[1]
    if desc[0] != Nodetype.BASE and desc[1][0][0] == Nodetype.NAME:
        return desc[1][0][1]
    return None


def _field(name: str, desc: FieldDesc, owner: str) -> dict[str, Any]:
    offset, capacity = 0, 0
    inner = desc
    if desc[0] == Nodetype.ARRAY:
        inner, capacity = desc[1]
        offset = _ARRAY
    elif desc[0] == Nodetype.SEQUENCE:
        inner, capacity = desc[1]
        offset = _BOUNDED_SEQUENCE if capacity else _UNBOUNDED_SEQUENCE
    string_capacity, nested = 0, ""
    if inner[0] == Nodetype.NAME:
        type_id = _NESTED
        nested = _ros_name(inner[1])
    else:
        base, string_capacity = inner[1]
        if base in ("string", "wstring") and string_capacity:
            type_id = _BOUNDED_STRING if base == "string" else _BOUNDED_WSTRING
        elif base in _TYPE_IDS:
            type_id = _TYPE_IDS[base]
        else:
            raise TypeDefinitionError(owner, name, f"type {base!r} has no type description id")
    return {
        "name": name,
        "type": {
            "type_id": type_id + offset,
            "capacity": capacity,
            "string_capacity": string_capacity,
            "nested_type_name": nested,
        },
    }
