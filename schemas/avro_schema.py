"""Avro schemas derived from ROS 2 message types: a pure function of the type definition.

Mapping (field order = ROS declaration order; constants go into the record's ``doc``):

==================================  ==========================================
ROS                                 Avro
==================================  ==========================================
bool                                boolean
byte, char, int8/16/32, uint8/16    int
uint32, int64, uint64               long (uint64 above 2**63-1 is refused)
float32 / float64                   float / double
string, string<=N                   string
uint8/byte/char arrays, sequences   bytes
other arrays and sequences          array
nested message                      record ``ros.<pkg>.msg.<Name>``
==================================  ==========================================

Each record is defined where it is first used (depth first) and referenced by its full name
afterwards. Every field carries its ROS declaration (``"ros_type": "float64[9]"``), so array
sizes and bounds survive; the top record carries ``ros_type`` and ``ros_type_hash``.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from rosbags.interfaces import Nodetype

from fleetlink.schemas.errors import TypeDefinitionError
from fleetlink.schemas.typehash import type_hash
from fleetlink.schemas.typestore import Distro, fields_of

if TYPE_CHECKING:
    from rosbags.interfaces.typing import FieldDesc
    from rosbags.typesys.store import Typestore

NAMESPACE_ROOT = "ros"

AVRO_PRIMITIVES: dict[str, str] = {
    "bool": "boolean",
    "byte": "int",
    "char": "int",
    "int8": "int",
    "uint8": "int",
    "int16": "int",
    "uint16": "int",
    "int32": "int",
    "uint32": "long",
    "int64": "long",
    "uint64": "long",
    "float32": "float",
    "float64": "double",
    "string": "string",
}
BYTES_ELEMENTS = frozenset({"uint8", "byte", "char"})


def avro_fullname(typename: str) -> str:
    """``sensor_msgs/msg/Imu`` -> ``ros.sensor_msgs.msg.Imu``."""
    return ".".join((NAMESPACE_ROOT, *typename.split("/")))


def avro_schema(ts: Typestore, typename: str, distro: Distro) -> dict[str, Any]:
    """The Avro schema (a JSON-compatible dict) of a ROS message type; same input, same output."""
    top = _Builder(ts).record(typename, None)
    top["ros_type_hash"] = type_hash(ts, typename, distro)
    return top


def ros_declaration(desc: FieldDesc) -> str:
    """The ``.msg`` spelling of a field type: ``float64[9]``, ``string<=8[]``, ``pkg/msg/T[<=3]``."""
    if desc[0] == Nodetype.BASE:
        base, bound = desc[1]
        return f"{base}<={bound}" if bound else base
    if desc[0] == Nodetype.NAME:
        return desc[1]
    inner, size = desc[1]
    suffix = f"[{size}]" if desc[0] == Nodetype.ARRAY else f"[<={size}]" if size else "[]"
    return ros_declaration(inner) + suffix


class _Builder:
    def __init__(self, ts: Typestore) -> None:
        self.ts = ts
        self.defined: set[str] = set()

    def record(self, typename: str, referenced_by: str | None) -> dict[str, Any]:
        fields = fields_of(self.ts, typename, referenced_by)
        self.defined.add(typename)
        namespace, _, name = avro_fullname(typename).rpartition(".")
        out: dict[str, Any] = {
            "type": "record",
            "name": name,
            "namespace": namespace,
            "doc": self._doc(typename),
            "fields": [
                {
                    "name": fname,
                    "type": self._type(desc, f"{typename}.{fname}"),
                    "ros_type": ros_declaration(desc),
                }
                for fname, desc in fields
            ],
            "ros_type": typename,
        }
        return out

    def _doc(self, typename: str) -> str:
        consts = self.ts.fielddefs[typename][0]
        doc = f"ROS 2 message {typename}."
        if consts:
            doc += " Constants: " + "; ".join(f"{ctype} {cname}={value!r}" for cname, ctype, value in consts)
        return doc

    def _type(self, desc: FieldDesc, where: str) -> Any:
        if desc[0] == Nodetype.BASE:
            return self._primitive(desc[1][0], where)
        if desc[0] == Nodetype.NAME:
            return self._named(desc[1], where)
        inner = desc[1][0]
        if inner[0] == Nodetype.BASE and inner[1][0] in BYTES_ELEMENTS:
            return "bytes"
        return {"type": "array", "items": self._type(inner, where)}

    def _named(self, typename: str, where: str) -> Any:
        if typename in self.defined:
            return avro_fullname(typename)
        return self.record(typename, where)

    @staticmethod
    def _primitive(base: str, where: str) -> str:
        avro = AVRO_PRIMITIVES.get(base)
        if avro is None:
            owner, _, field = where.rpartition(".")
            raise TypeDefinitionError(owner, field, f"ROS type {base!r} has no Avro mapping")
        return avro
