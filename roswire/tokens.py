"""rmw_zenoh liveliness tokens: build and parse (rmw_zenoh.md §3).

::

    node:     @ros2_lv/<dom>/<zid>/<nid>/<nid>/NN/<enclave>/<namespace>/<node>
    endpoint: @ros2_lv/<dom>/<zid>/<nid>/<eid>/<KIND>/<enclave>/<namespace>/<node>
              /<topic>/<dds_type>/<hash>/<qos>

Enclave, namespace and topic are mangled (``/`` -> ``%``). Anything that does not follow the
grammar raises :class:`TokenError`; callers count those and carry on.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from enum import Enum

from fleetlink.roswire.errors import InvalidNameError, QosParseError, TokenError
from fleetlink.roswire.gid import entity_gid
from fleetlink.roswire.names import (
    dds_type_name,
    is_valid_type_hash,
    join_namespace,
    mangle,
    ros_type_name,
    unmangle,
    validate_namespace,
    validate_node_name,
    validate_topic,
)
from fleetlink.roswire.qos import QoS

PREFIX = "@ros2_lv"
NODE_CHUNKS = 9
ENDPOINT_CHUNKS = 13
_ZID_RE = re.compile(r"[0-9a-f]{1,32}")


class EntityKind(Enum):
    """The kind chunk of a liveliness token: node, publisher, subscription, service server or client."""

    NODE = "NN"
    PUBLISHER = "MP"
    SUBSCRIPTION = "MS"
    SERVICE_SERVER = "SS"
    SERVICE_CLIENT = "SC"


ENDPOINT_KINDS = frozenset(k for k in EntityKind if k is not EntityKind.NODE)


def liveliness_prefix(domain: int) -> str:
    """The key expression that matches every token of a domain."""
    return f"{PREFIX}/{domain}/**"


@dataclass(frozen=True)
class NodeInfo:
    """What a node (``NN``) token says."""

    domain: int
    zid: str
    nid: int
    enclave: str
    namespace: str
    name: str
    key: str = field(compare=False)

    @property
    def fqn(self) -> str:
        """The node's fully qualified name (namespace and name)."""
        return join_namespace(self.namespace, self.name)

    @property
    def node_id(self) -> tuple[str, int]:
        """Nodes are identified by (session zid, node id)."""
        return (self.zid, self.nid)


@dataclass(frozen=True)
class EndpointInfo:
    """What an endpoint (``MP``, ``MS``, ``SS``, ``SC``) token says."""

    domain: int
    zid: str
    nid: int
    eid: int
    kind: EntityKind
    enclave: str
    namespace: str
    node_name: str
    topic: str
    dds_type: str
    ros_type: str
    type_hash: str
    qos: QoS
    key: str = field(compare=False)

    @property
    def node_id(self) -> tuple[str, int]:
        """The (session zid, node id) of the node the endpoint belongs to."""
        return (self.zid, self.nid)

    @property
    def node_fqn(self) -> str:
        """The fully qualified name of the endpoint's node."""
        return join_namespace(self.namespace, self.node_name)

    @property
    def gid(self) -> bytes:
        """The endpoint's 16-byte GID, derived from its token key."""
        return entity_gid(self.key)


Entity = NodeInfo | EndpointInfo


def node_token(domain: int, zid: str, nid: int, namespace: str, name: str, *, enclave: str = "/") -> str:
    """The liveliness key of a node's ``NN`` token; ``InvalidNameError`` for a bad namespace or name."""
    validate_namespace(namespace)
    validate_node_name(name)
    return (
        f"{PREFIX}/{domain}/{zid}/{nid}/{nid}/{EntityKind.NODE.value}/"
        f"{mangle(enclave or '/')}/{mangle(namespace)}/{name}"
    )


def endpoint_token(
    *,
    domain: int,
    zid: str,
    nid: int,
    eid: int,
    kind: EntityKind,
    namespace: str,
    node_name: str,
    topic: str,
    typename: str,
    type_hash: str,
    qos: QoS,
    enclave: str = "/",
) -> str:
    """The liveliness key of an endpoint's token.

    Raises :class:`TokenError` for a node kind and ``InvalidNameError`` for a bad name or type hash.
    """
    if kind not in ENDPOINT_KINDS:
        raise TokenError(str(kind), "an endpoint token needs kind MP, MS, SS or SC")
    validate_namespace(namespace)
    validate_node_name(node_name)
    validate_topic(topic)
    if not is_valid_type_hash(type_hash):
        raise InvalidNameError(type_hash, "not a type hash")
    return (
        f"{PREFIX}/{domain}/{zid}/{nid}/{eid}/{kind.value}/{mangle(enclave or '/')}/"
        f"{mangle(namespace)}/{node_name}/{mangle(topic)}/{dds_type_name(typename)}/{type_hash}/"
        f"{qos.to_keyexpr()}"
    )


def _decimal(key: str, what: str, text: str) -> int:
    if not text.isascii() or not text.isdigit():
        raise TokenError(key, f"{what} {text!r} is not a decimal number")
    return int(text)


def parse_token(key: str) -> NodeInfo | EndpointInfo:
    """Parse a node or endpoint token key; raise :class:`TokenError` when malformed."""
    chunks = key.split("/")
    if chunks[0] != PREFIX:
        raise TokenError(key, f"does not start with {PREFIX!r}")
    if len(chunks) not in (NODE_CHUNKS, ENDPOINT_CHUNKS):
        raise TokenError(key, f"has {len(chunks)} chunks, expected {NODE_CHUNKS} or {ENDPOINT_CHUNKS}")
    _, dom, zid, nid_text, eid_text, kind_text, enclave_m, ns_m, node_name = chunks[:9]
    domain = _decimal(key, "domain", dom)
    if not _ZID_RE.fullmatch(zid):
        raise TokenError(key, f"zid {zid!r} is not lowercase hex")
    nid = _decimal(key, "node id", nid_text)
    eid = _decimal(key, "entity id", eid_text)
    try:
        kind = EntityKind(kind_text)
    except ValueError:
        raise TokenError(key, f"unknown entity kind {kind_text!r}") from None
    try:
        enclave = unmangle(enclave_m)
        namespace = validate_namespace(unmangle(ns_m))
        validate_node_name(node_name)
    except InvalidNameError as exc:
        raise TokenError(key, f"{exc.reason} ({exc.name!r})") from None
    if kind is EntityKind.NODE:
        if len(chunks) != NODE_CHUNKS:
            raise TokenError(key, "a node (NN) token has 9 chunks")
        if eid != nid:
            raise TokenError(key, f"node token entity id {eid} differs from node id {nid}")
        return NodeInfo(domain, zid, nid, enclave, namespace, node_name, key)
    if len(chunks) != ENDPOINT_CHUNKS:
        raise TokenError(key, f"an endpoint ({kind.value}) token has 13 chunks")
    topic_m, dds_type, type_hash, qos_text = chunks[9:]
    try:
        topic = validate_topic(unmangle(topic_m))
        ros_type = ros_type_name(dds_type)
    except InvalidNameError as exc:
        raise TokenError(key, f"{exc.reason} ({exc.name!r})") from None
    if not is_valid_type_hash(type_hash):
        raise TokenError(key, f"hash chunk {type_hash!r} is not a type hash")
    try:
        qos = QoS.parse(qos_text)
    except QosParseError as exc:
        raise TokenError(key, exc.reason) from None
    return EndpointInfo(
        domain,
        zid,
        nid,
        eid,
        kind,
        enclave,
        namespace,
        node_name,
        topic,
        dds_type,
        ros_type,
        type_hash,
        qos,
        key,
    )
