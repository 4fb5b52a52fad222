"""A command's Avro value -> the CDR payload of its ROS type (schemas codecs).

When the writer schema is the one fleetlink derives from the ROS definition (same
fingerprint), the generated ``avro_to_cdr`` converter runs on the body directly. Otherwise
(a producer wrote with an evolved or hand-made schema) the body is first read with Avro schema
resolution, writer -> the ROS type's schema, and written again in that schema.
"""

from __future__ import annotations

import copy
import io
import json
import threading
from typing import TYPE_CHECKING, Any

import fastavro

from fleetlink.repeater.errors import ConversionError
from fleetlink.schemas.codec import RESOLVE_ERRORS, Codec, get_codec
from fleetlink.schemas.errors import SchemaError
from fleetlink.schemas.single_object import fingerprint
from fleetlink.schemas.typestore import Distro
from fleetlink.wire.commands import CommandEnvelope

if TYPE_CHECKING:
    from rosbags.typesys.store import Typestore


class Converter:
    """Turns the Avro value of a command envelope into the CDR payload of its ROS type.

    Thread-safe; the fingerprints of the types' own schemas and parsed writer schemas are cached.
    """

    def __init__(self, typestore: Typestore, distro: Distro) -> None:
        self.typestore = typestore
        self.distro: Distro = distro
        self._lock = threading.Lock()
        self._own_fp: dict[str, bytes] = {}
        self._writers: dict[bytes, Any] = {}

    def codec(self, env: CommandEnvelope) -> Codec:
        """The codec of ``env``'s ROS type; raises ``ConversionError`` when the type cannot be loaded."""
        try:
            return get_codec(self.typestore, env.ros_type, self.distro)
        except SchemaError as exc:
            raise ConversionError(env.command_id, env.ros_type, str(exc)) from None

    def is_own_schema(self, env: CommandEnvelope) -> bool:
        """Whether ``env`` was written with the schema fleetlink derives from its ROS type."""
        return env.schema_fp == self._fingerprint(self.codec(env))

    def to_cdr(self, env: CommandEnvelope, writer_schema: str | None) -> bytes:
        """The CDR payload for ``env``; ``writer_schema`` is needed unless it is the type's own."""
        codec = self.codec(env)
        body = env.body
        if env.schema_fp != self._fingerprint(codec):
            if writer_schema is None:
                raise ConversionError(
                    env.command_id, env.ros_type, f"writer schema {env.schema_fp.hex()} is unknown here"
                )
            writer = self._writer(env, writer_schema)
            try:
                datum = fastavro.schemaless_reader(io.BytesIO(body), writer, codec.parsed_schema)
            except RESOLVE_ERRORS as exc:
                raise ConversionError(
                    env.command_id, env.ros_type, f"value does not resolve to the type's schema: {exc}"
                ) from None
            if not isinstance(datum, dict):
                raise ConversionError(env.command_id, env.ros_type, "value is not a record")
            try:
                body = codec.encode_datum(datum)
            except SchemaError as exc:
                raise ConversionError(env.command_id, env.ros_type, str(exc)) from None
        try:
            return codec.avro_to_cdr(body)
        except SchemaError as exc:
            raise ConversionError(env.command_id, env.ros_type, str(exc)) from None

    def _fingerprint(self, codec: Codec) -> bytes:
        with self._lock:
            fp = self._own_fp.get(codec.typename)
            if fp is None:
                fp = self._own_fp[codec.typename] = fingerprint(codec.schema)
            return fp

    def _writer(self, env: CommandEnvelope, text: str) -> Any:
        with self._lock:
            parsed = self._writers.get(env.schema_fp)
        if parsed is not None:
            return parsed
        try:
            parsed = fastavro.parse_schema(copy.deepcopy(json.loads(text)))
        except (ValueError, TypeError, KeyError, fastavro.schema.SchemaParseException) as exc:
            raise ConversionError(env.command_id, env.ros_type, f"writer schema is unusable: {exc}") from None
        with self._lock:
            self._writers[env.schema_fp] = parsed
        return parsed
