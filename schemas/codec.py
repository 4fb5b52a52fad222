"""Per-type converters between CDR payloads and Avro binary records.

``get_codec(ts, typename, distro)`` builds (once, then cached per type store) a :class:`Codec`
whose ``cdr_to_avro`` / ``avro_to_cdr`` / ``decode`` are functions generated for that type. Round trips are
byte-exact: ``avro_to_cdr(cdr_to_avro(x)) == x`` for every CDR message rosbags or Fast-CDR
writes (little-endian; big-endian input is accepted and converted, trailing alignment bytes
are dropped).
"""

from __future__ import annotations

import copy
import io
import threading
import weakref
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

import fastavro
from fastavro.read import SchemaResolutionError

from fleetlink.schemas.avro_schema import avro_schema
from fleetlink.schemas.errors import DecodeError, EncodeError, ValueRangeError
from fleetlink.schemas.gen_avro_cdr import AvroToCdr
from fleetlink.schemas.gen_cdr_avro import CdrToAvro
from fleetlink.schemas.gen_cdr_dict import CdrToDict
from fleetlink.schemas.layout import Record, build
from fleetlink.schemas.typestore import Distro, normalize_typename

if TYPE_CHECKING:
    from rosbags.typesys.store import Typestore

Converter = Callable[[bytes], bytes]

RESOLVE_ERRORS = (
    SchemaResolutionError,
    EOFError,
    ValueError,
    TypeError,
    KeyError,
    IndexError,
    UnicodeDecodeError,
)
"""What fastavro raises reading a body written with one schema into another (schema resolution)."""


class Codec:
    """CDR <-> Avro for one ROS type; build with :func:`get_codec`."""

    cdr_to_avro: Converter
    """CDR payload (with its 4-byte encapsulation header) -> Avro binary body."""
    avro_to_cdr: Converter
    """Avro binary body -> CDR payload (``00 01 00 00`` header, little-endian)."""
    decode: Callable[[bytes], dict[str, Any]]
    """CDR payload -> the dict an Avro reader returns for it (bytes for uint8[], lists for arrays)."""

    def __init__(self, ts: Typestore, typename: str, distro: Distro) -> None:
        self.typename = typename
        self.distro = distro
        self.schema: dict[str, Any] = avro_schema(ts, typename, distro)
        self.parsed_schema: Any = fastavro.parse_schema(copy.deepcopy(self.schema))
        self.type_hash: str = self.schema["ros_type_hash"]
        self._root: Record = build(ts, typename)
        self._big_endian: dict[str, Callable[[bytes], Any]] = {}
        self.cdr_to_avro = CdrToAvro(self._root, little_endian=True).compile(self._namespace("avro"))
        self.avro_to_cdr = AvroToCdr(self._root).compile(self._namespace("cdr"))
        self.decode = CdrToDict(self._root, little_endian=True).compile_decoder(self._namespace("dict"))

    @property
    def layout(self) -> Record:
        """The type's node tree (what the converters are generated from)."""
        return self._root

    def read_avro(self, body: bytes) -> dict[str, Any]:
        """An Avro body of this type read with fastavro (same shape as :attr:`decode`)."""
        try:
            datum = fastavro.schemaless_reader(io.BytesIO(body), self.parsed_schema, None)
        except (EOFError, ValueError, IndexError, UnicodeDecodeError) as exc:
            raise DecodeError(self.typename, 0, f"not an Avro {self.typename}: {exc}", body) from exc
        if not isinstance(datum, dict):
            raise DecodeError(self.typename, 0, "Avro reader returned no record", body)
        return datum

    def encode_datum(self, datum: dict[str, Any]) -> bytes:
        """Avro binary body of a datum shaped like :attr:`decode`'s result.

        Checks what Avro checks (field presence, types, long range); ROS ranges such as uint8 are
        checked when the body is turned into CDR (:attr:`avro_to_cdr`).
        """
        out = io.BytesIO()
        try:
            fastavro.schemaless_writer(out, self.parsed_schema, datum)
        except (ValueError, TypeError, KeyError, AttributeError, OverflowError) as exc:
            raise EncodeError(self.typename, f"{type(exc).__name__}: {exc}") from exc
        return out.getvalue()

    def _namespace(self, output: str) -> dict[str, Any]:
        def other_encapsulation(buf: bytes) -> Any:
            return self._other_encapsulation(buf, output)

        return {
            "_DecodeError": DecodeError,
            "_ValueRangeError": ValueRangeError,
            "_TYPENAME": self.typename,
            "_other_encapsulation": other_encapsulation,
        }

    def _other_encapsulation(self, buf: bytes, output: str) -> Any:
        if len(buf) < 4:
            reason = f"{len(buf)} bytes cannot hold the 4-byte CDR encapsulation header"
            raise DecodeError(self.typename, len(buf), reason, buf)
        if buf[0] != 0 or buf[1] not in (0, 1):
            raise DecodeError(
                self.typename,
                0 if buf[0] else 1,
                f"unsupported encapsulation {buf[:2].hex(' ')}: expected 00 01 (CDR little-endian) "
                "or 00 00 (CDR big-endian)",
                buf,
            )
        convert = self._big_endian.get(output)
        if convert is None:
            if output == "dict":
                convert = CdrToDict(self._root, little_endian=False).compile_decoder(self._namespace(output))
            else:
                convert = CdrToAvro(self._root, little_endian=False).compile(self._namespace(output))
            self._big_endian[output] = convert
        return convert(buf)


_CACHE: weakref.WeakKeyDictionary[Typestore, dict[tuple[str, str], Codec]] = weakref.WeakKeyDictionary()
_LOCK = threading.Lock()


def get_codec(ts: Typestore, typename: str, distro: Distro) -> Codec:
    """The (cached) codec of ``typename`` in ``ts``; raises ``UnknownTypeError`` for unknown types."""
    typename = normalize_typename(typename)
    with _LOCK:
        per_store = _CACHE.setdefault(ts, {})
        codec = per_store.get((typename, distro))
    if codec is None:
        codec = Codec(ts, typename, distro)
        with _LOCK:
            codec = per_store.setdefault((typename, distro), codec)
    return codec
