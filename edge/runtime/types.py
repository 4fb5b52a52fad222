"""Codecs for the ROS types the edge meets, from its type store (built once, then cached)."""

from __future__ import annotations

import threading
from typing import TYPE_CHECKING, Literal

from fleetlink.schemas.codec import Codec, get_codec
from fleetlink.schemas.errors import SchemaError, UnknownTypeError
from fleetlink.schemas.typestore import Distro

if TYPE_CHECKING:
    from rosbags.typesys.store import Typestore

ConfigDistro = Literal["humble", "iron", "jazzy", "kilted", "rolling"]

_SCHEMA_DISTRO: dict[str, Distro] = {
    "humble": "humble",
    "iron": "jazzy",  # iron hashes types like jazzy (RIHS01); its standard types are jazzy's
    "jazzy": "jazzy",
    "kilted": "kilted",
    "rolling": "kilted",  # the newest store fleetlink ships
}


def schema_distro(distro: ConfigDistro) -> Distro:
    """The type-store distro used for a configured ROS distro."""
    return _SCHEMA_DISTRO[distro]


class TypeStoreCodecs:
    """``codec(typename)`` from one type store; types that failed once fail fast afterwards."""

    def __init__(self, typestore: Typestore, distro: Distro) -> None:
        self.typestore = typestore
        self.distro: Distro = distro
        self._failed: dict[str, SchemaError] = {}
        self._lock = threading.Lock()

    def codec(self, typename: str) -> Codec:
        """The codec of ``typename``; raises ``SchemaError`` (``UnknownTypeError`` for a name the type
        store lacks), and for a type that failed once raises the same error again at once."""
        failed = self._failed.get(typename)
        if failed is not None:
            raise failed
        try:
            return get_codec(self.typestore, typename, self.distro)
        except SchemaError as exc:
            with self._lock:
                self._failed[typename] = exc
            raise
        except KeyError:  # a name rosbags does not know at all
            error = UnknownTypeError(typename)
            with self._lock:
                self._failed[typename] = error
            raise error from None
