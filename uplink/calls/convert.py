"""ROS types of the call mappings at the uplink: Kafka values (any Avro schema the type's own
schema can read) -> CDR for the robots, and the robots' CDR -> Avro for Kafka."""

from __future__ import annotations

import io
from collections.abc import Sequence
from typing import TYPE_CHECKING, Any, Protocol

import fastavro

from fleetlink.schemas.codec import RESOLVE_ERRORS, Codec, get_codec
from fleetlink.schemas.errors import SchemaError
from fleetlink.schemas.single_object import fingerprint
from fleetlink.schemas.typestore import Distro
from fleetlink.uplink.commands.decode import DecodedValue
from fleetlink.uplink.commands.errors import UndecodableValueError

if TYPE_CHECKING:
    from rosbags.typesys.store import Typestore


class _Mapping(Protocol):
    @property
    def type(self) -> str: ...


class _Ros(Protocol):
    @property
    def distro(self) -> Distro: ...
    @property
    def message_paths(self) -> Any: ...


class UplinkConfigLike(Protocol):
    """What :func:`load_call_types` reads of the uplink config: the call mappings and the ROS section."""

    @property
    def services(self) -> Sequence[_Mapping]:
        """The service mappings (only their ``type`` is read)."""

    @property
    def actions(self) -> Sequence[_Mapping]:
        """The action mappings (only their ``type`` is read)."""

    @property
    def ros(self) -> _Ros:
        """The ROS distro and the folders of extra interface packages."""


class CallTypes:
    """Codecs of the call mappings' ROS types: Kafka's Avro values to CDR for the robots, and their CDR
    back to Avro."""

    def __init__(self, typestore: Typestore, distro: Distro) -> None:
        self.typestore = typestore
        self.distro: Distro = distro

    def codec(self, typename: str) -> Codec:
        """The codec of a request, goal, response, feedback or result type (``SchemaError``)."""
        return get_codec(self.typestore, typename, self.distro)

    def check(self, typename: str, parts: tuple[str, ...]) -> None:
        """Raise ``SchemaError`` unless every part (``_Request`` …) of ``typename`` is known."""
        for part in parts:
            self.codec(f"{typename}{part}")

    def to_cdr(self, typename: str, decoded: DecodedValue) -> bytes:
        """The CDR of a decoded Kafka value; ``UndecodableValueError`` when it is not one."""
        try:
            codec = self.codec(typename)
        except SchemaError as exc:
            raise UndecodableValueError(f"type {typename}: {exc}", decoded.body) from None
        body = decoded.body
        if decoded.writer.fingerprint != fingerprint(codec.schema):
            try:
                datum: Any = fastavro.schemaless_reader(
                    io.BytesIO(body), decoded.writer.parsed, codec.parsed_schema
                )
                body = codec.encode_datum(datum)
            except (*RESOLVE_ERRORS, SchemaError) as exc:
                raise UndecodableValueError(
                    f"the value does not resolve to {typename}'s schema: {exc}", decoded.body
                ) from None
        try:
            return codec.avro_to_cdr(body)
        except SchemaError as exc:
            raise UndecodableValueError(f"the value is no {typename}: {exc}", decoded.body) from None

    def to_avro(self, typename: str, cdr: bytes) -> bytes:
        """The Avro body of a CDR message (``SchemaError`` when it is not one)."""
        return self.codec(typename).cdr_to_avro(cdr)


_PARTS = {"services": ("_Request", "_Response"), "actions": ("_Goal", "_Feedback", "_Result")}


def load_call_types(config: UplinkConfigLike) -> CallTypes | None:
    """The types of the config's service and action mappings (None without any); a
    ``ConfigError`` naming the YAML path when a type or package is missing or unreadable."""
    from fleetlink.common.errors import ConfigError
    from fleetlink.schemas.typestore import load_typestore

    if not config.services and not config.actions:
        return None
    try:
        types = CallTypes(load_typestore(config.ros.distro, config.ros.message_paths), config.ros.distro)
    except SchemaError as exc:
        raise ConfigError(f"ros.message_paths: cannot load the interface types: {exc}") from None
    for section, mappings in (("services", config.services), ("actions", config.actions)):
        for index, mapping in enumerate(mappings):
            try:
                types.check(mapping.type, _PARTS[section])
            except SchemaError as exc:
                raise ConfigError(
                    f"{section}[{index}].type: {mapping.type} is not usable here ({exc}); "
                    "add its package to ros.message_paths"
                ) from None
    return types
