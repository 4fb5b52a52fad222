"""ROS names on the rmw_zenoh wire: mangling, DDS type names, data keys (rmw_zenoh.md §2, §12).

Pure functions, no I/O. A data key is ``<domain>/<topic without outer '/'>/<dds type>/<hash>``;
liveliness tokens carry names *mangled* (every ``/`` replaced by ``%``).
"""

from __future__ import annotations

import re
from dataclasses import dataclass

from fleetlink.common.names import ROS_SEGMENT, ros_segments_problem, ros_topic_problem
from fleetlink.roswire.errors import InvalidNameError, KeyParseError

HASH_NOT_SUPPORTED = "TypeHashNotSupported"
"""The hash chunk Humble's rmw_zenoh writes (Humble has no type hashes)."""

_HASH_RE = re.compile(r"RIHS[0-9]{2}_[0-9a-f]+")
_RIHS01_RE = re.compile(r"RIHS01_[0-9a-f]{64}")
TYPE_KINDS = ("msg", "srv", "action")


def mangle(name: str) -> str:
    """``/robot1/cmd_vel`` -> ``%robot1%cmd_vel`` (how names appear inside token chunks)."""
    return name.replace("/", "%")


def unmangle(chunk: str) -> str:
    """Inverse of :func:`mangle`."""
    return chunk.replace("%", "/")


def _check_tokens(name: str, tokens: list[str]) -> None:
    problem = ros_segments_problem(tokens)
    if problem is not None:
        raise InvalidNameError(name, problem)


def validate_topic(name: str) -> str:
    """Check a fully qualified topic or service name (``/a/b``); return it unchanged."""
    problem = ros_topic_problem(name)
    if problem is not None:
        raise InvalidNameError(name, problem)
    return name


def validate_namespace(namespace: str) -> str:
    """Check a node namespace (``/`` or ``/a/b``); return it unchanged."""
    if namespace == "/":
        return namespace
    if not namespace.startswith("/"):
        raise InvalidNameError(namespace, "namespace must start with '/'")
    _check_tokens(namespace, namespace[1:].split("/"))
    return namespace


def validate_node_name(name: str) -> str:
    """Check a node's base name (one segment, no '/'); return it unchanged."""
    if not name:
        raise InvalidNameError(name, "empty node name")
    _check_tokens(name, [name])
    return name


def join_namespace(namespace: str, name: str) -> str:
    """``("/", "odom") -> "/odom"``, ``("/tb4_01", "odom") -> "/tb4_01/odom"``."""
    return f"/{name}" if namespace == "/" else f"{namespace}/{name}"


def resolve_topic(name: str, namespace: str = "/", node: str | None = None) -> str:
    """Expand a relative (``odom``) or private (``~/odom``) name to a fully qualified one."""
    validate_namespace(namespace)
    if name.startswith("/"):
        return validate_topic(name)
    if name == "~" or name.startswith("~/"):
        if node is None:
            raise InvalidNameError(name, "a private name needs a node name")
        base = join_namespace(namespace, validate_node_name(node))
        return validate_topic(base if name == "~" else f"{base}/{name[2:]}")
    if not name:
        raise InvalidNameError(name, "empty name")
    return validate_topic(join_namespace(namespace, name))


def first_segment(name: str) -> str | None:
    """``/tb4_07/sensors`` -> ``tb4_07``; ``/`` -> None."""
    parts = name.strip("/").split("/", 1)
    return parts[0] or None


# --- type names --------------------------------------------------------------------------


def split_ros_type(typename: str) -> tuple[str, str, str]:
    """``std_msgs/msg/String`` -> ``("std_msgs", "msg", "String")``, validated."""
    parts = typename.split("/")
    if len(parts) != 3:
        raise InvalidNameError(typename, "a ROS type is 'pkg/msg|srv|action/Name'")
    pkg, kind, base = parts
    if kind not in TYPE_KINDS:
        raise InvalidNameError(typename, f"kind {kind!r} is not one of {', '.join(TYPE_KINDS)}")
    for part in (pkg, base):
        if not ROS_SEGMENT.fullmatch(part):
            raise InvalidNameError(typename, f"{part!r} is not an identifier")
    return pkg, kind, base


def dds_type_name(typename: str) -> str:
    """``std_msgs/msg/String`` -> ``std_msgs::msg::dds_::String_`` (Fast-CDR type-support name)."""
    pkg, kind, base = split_ros_type(typename)
    return f"{pkg}::{kind}::dds_::{base}_"


def ros_type_name(dds_type: str) -> str:
    """``std_msgs::msg::dds_::String_`` -> ``std_msgs/msg/String``.

    A service request/response type-support name (``…::srv::dds_::AddTwoInts_Request_``) maps
    to the service type (``…/srv/AddTwoInts``), which is what service keys and tokens carry.
    """
    parts = dds_type.split("::")
    if len(parts) != 4 or parts[2] != "dds_":
        raise InvalidNameError(dds_type, "a DDS type name is 'pkg::kind::dds_::Name_'")
    pkg, kind, _, base_ = parts
    if not base_.endswith("_") or len(base_) < 2:
        raise InvalidNameError(dds_type, "the type name must end with '_'")
    base = base_[:-1]
    typename = f"{pkg}/{kind}/{base}"
    split_ros_type(typename)
    if kind == "srv":
        return f"{pkg}/{kind}/{service_base(base)}"
    return typename


def service_base(base: str) -> str:
    """``AddTwoInts_Request`` / ``AddTwoInts_Response`` -> ``AddTwoInts`` (cut at the last suffix)."""
    for suffix in ("_Request", "_Response"):
        pos = base.rfind(suffix)
        if pos > 0 and pos + len(suffix) == len(base):
            return base[:pos]
    return base


def service_key_type(dds_type: str) -> str:
    """The type chunk rmw_zenoh puts in service keys: the request type name with ``Request_`` cut."""
    return dds_type_name(ros_type_name(dds_type))


def is_valid_type_hash(text: str) -> bool:
    """``RIHSnn_<hex>`` (RIHS01 must have 64 hex digits) or Humble's ``TypeHashNotSupported``."""
    if text == HASH_NOT_SUPPORTED:
        return True
    if text.startswith("RIHS01_"):
        return bool(_RIHS01_RE.fullmatch(text))
    return bool(_HASH_RE.fullmatch(text))


# --- data keys ---------------------------------------------------------------------------


@dataclass(frozen=True)
class DataKey:
    """The parts of an rmw_zenoh data key."""

    domain: int
    topic: str
    dds_type: str
    ros_type: str
    type_hash: str

    def __str__(self) -> str:
        return f"{self.domain}/{self.topic.strip('/')}/{self.dds_type}/{self.type_hash}"


def _check_domain(domain: int) -> int:
    if domain < 0:
        raise InvalidNameError(str(domain), "domain id must be >= 0")
    return domain


def data_key(domain: int, topic: str, typename: str, type_hash: str) -> str:
    """The key a publisher puts on: ``0/chatter/std_msgs::msg::dds_::String_/RIHS01_…``."""
    if not is_valid_type_hash(type_hash):
        raise InvalidNameError(type_hash, "not a type hash (RIHS01_<64 hex> or TypeHashNotSupported)")
    return f"{_check_domain(domain)}/{validate_topic(topic).strip('/')}/{dds_type_name(typename)}/{type_hash}"


def data_key_expr(domain: int, topic: str, typename: str | None = None, type_hash: str | None = None) -> str:
    """A subscription key expression: unknown type or hash become ``*`` (match any)."""
    dds = dds_type_name(typename) if typename is not None else "*"
    if type_hash is not None and not is_valid_type_hash(type_hash):
        raise InvalidNameError(type_hash, "not a type hash")
    return f"{_check_domain(domain)}/{validate_topic(topic).strip('/')}/{dds}/{type_hash or '*'}"


def parse_data_key(key: str) -> DataKey:
    """Split a data key from its ends: first chunk domain, last hash, second-to-last type."""
    chunks = key.split("/")
    if len(chunks) < 4:
        raise KeyParseError(key, f"needs at least 4 chunks, has {len(chunks)}")
    domain_text, *topic_chunks, dds_type, type_hash = chunks
    if not domain_text.isdigit() or not domain_text.isascii():
        raise KeyParseError(key, f"domain chunk {domain_text!r} is not a decimal number")
    topic = "/" + "/".join(topic_chunks)
    try:
        validate_topic(topic)
        ros_type = ros_type_name(dds_type)
    except InvalidNameError as exc:
        raise KeyParseError(key, exc.reason + f" ({exc.name!r})") from None
    if not is_valid_type_hash(type_hash):
        raise KeyParseError(key, f"hash chunk {type_hash!r} is not a type hash")
    return DataKey(int(domain_text), topic, dds_type, ros_type, type_hash)
