"""Object keys and content types (pure).

A key names the record it belongs to and the bytes it holds::

    <prefix><site>/<robot>/<mapping>/<source stamp ns>-<sha256 hex><extension>

so an upload tried again (a timeout, a restart) writes the same object, and two records never
share a key unless they are the same record with the same bytes. ``_`` stands for a mapping
without a robot.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from fleetlink.edge.stages.images import content_type_of

EXTENSIONS = {"image/jpeg": ".jpg", "image/png": ".png"}
OCTETS = "application/octet-stream"


def content_type_for(value: Mapping[str, Any]) -> str:
    """The MIME type of a message's payload: from a ``format`` text field (CompressedImage:
    ``jpeg``, ``rgb8; png compressed bgr8``), else ``application/octet-stream``."""
    text = value.get("format")
    return content_type_of(text) if isinstance(text, str) else OCTETS


def object_key(
    *, prefix: str, site: str, robot: str | None, mapping: str, stamp_ns: int, sha256: str, content_type: str
) -> str:
    """The object key of a payload: ``<prefix><site>/<robot>/<mapping>/<stamp ns>-<sha256><extension>``,
    the extension from the content type (``.bin`` when unknown)."""
    extension = EXTENSIONS.get(content_type, ".bin")
    return f"{prefix}{site}/{robot or '_'}/{mapping}/{stamp_ns}-{sha256}{extension}"
