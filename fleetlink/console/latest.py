"""The latest value of a robot's topics, read when a robot page asks (the edge's console).

Nothing is kept on the data path: ``LatestValues.read(topics)`` subscribes to each topic on the
edge's Zenoh session for at most ``wait_s``, takes the first sample of each, decodes it with
the edge's type store and answers it as JSON-ready data (``plain``: numbers, text, nested
fields; long arrays cut to their first ``MAX_ITEMS`` items, bytes as hex). A value that carries
a link (a string field ``url`` or ``uri`` starting with ``http``; an image record pointing to
where the picture is kept) is answered with it as ``link``, for the page to show.

A camera's picture (``sensor_msgs/msg/CompressedImage`` in JPEG or PNG, or a raw
``sensor_msgs/msg/Image`` the console compresses to JPEG when the images extra is installed) is
answered as ``picture``, a ``data:`` URL the page shows as it is (at most ``MAX_PICTURE_BYTES``).

Over Zenoh the fleet console asks ``fleetlink/<site>/console/latest/<robot>`` (the admin
token as the attachment, as for every console key).
"""

from __future__ import annotations

import base64
import math
import threading
import time
from collections.abc import Callable, Sequence
from typing import Any

import zenoh

from fleetlink.edge.stages.images import ImageError, compress, content_type_of
from fleetlink.roswire.names import data_key_expr, parse_data_key

MAX_ITEMS = 32
MAX_DEPTH = 8
MAX_PICTURE_BYTES = 2 << 20
"""The largest picture sent to a page (bytes before base64)."""


def plain(value: Any, depth: int = 0) -> Any:  # noqa: PLR0911 - one return per kind of value
    """A decoded ROS message (rosbags dataclasses, numpy arrays) as JSON-ready data."""
    if depth > MAX_DEPTH:
        return "…"
    if value is None or isinstance(value, bool | int | str):
        return value
    if isinstance(value, float):
        return value if math.isfinite(value) else str(value)
    if isinstance(value, bytes | bytearray):
        return bytes(value[: MAX_ITEMS * 4]).hex() + ("…" if len(value) > MAX_ITEMS * 4 else "")
    tolist = getattr(value, "tolist", None)
    if callable(tolist) and hasattr(value, "shape"):
        items = tolist()
        if isinstance(items, list):
            cut = [plain(v, depth + 1) for v in items[:MAX_ITEMS]]
            return cut + ([f"… {len(items) - MAX_ITEMS} more"] if len(items) > MAX_ITEMS else [])
        return plain(items, depth + 1)
    if isinstance(value, list | tuple):
        cut = [plain(v, depth + 1) for v in value[:MAX_ITEMS]]
        return cut + ([f"… {len(value) - MAX_ITEMS} more"] if len(value) > MAX_ITEMS else [])
    fields = getattr(value, "__dataclass_fields__", None)
    if fields is not None:
        return {name: plain(getattr(value, name), depth + 1) for name in fields if name != "__msgtype__"}
    if isinstance(value, dict):
        return {str(k): plain(v, depth + 1) for k, v in list(value.items())[:MAX_ITEMS]}
    return str(value)


def link_of(value: Any) -> str | None:
    """A URL the value points to (``url`` / ``uri`` fields, at the top or one level down)."""
    if not isinstance(value, dict):
        return None
    for candidate in (value, *[v for v in value.values() if isinstance(v, dict)]):
        for name in ("url", "uri"):
            found = candidate.get(name)
            if isinstance(found, str) and found.startswith(("http://", "https://")):
                return found
    return None


def picture_of(typename: str, message: Any) -> str | None:
    """A ``data:`` URL of the picture ``message`` holds (a compressed or raw camera image), or
    None: not an image, an encoding the console cannot show, or larger than ``MAX_PICTURE_BYTES``."""
    data: bytes | None = None
    content_type = ""
    if typename == "sensor_msgs/msg/CompressedImage":
        content_type = content_type_of(str(getattr(message, "format", "")))
        data = bytes(getattr(message, "data", b""))
    elif typename == "sensor_msgs/msg/Image":
        data, content_type = _jpeg_of(message)
    if not data or not content_type.startswith("image/") or len(data) > MAX_PICTURE_BYTES:
        return None
    return f"data:{content_type};base64,{base64.b64encode(data).decode()}"


def _jpeg_of(message: Any) -> tuple[bytes | None, str]:
    fields = {name: getattr(message, name, None) for name in ("encoding", "height", "width", "step", "data")}
    fields["is_bigendian"] = getattr(message, "is_bigendian", 0)
    try:
        jpeg, _format = compress(fields, "jpeg", quality=70)
    except (ImageError, ImportError, ValueError, TypeError):  # no pillow, or not a picture we show
        return None, ""
    return jpeg, "image/jpeg"


class LatestValues:
    """Reads the latest value of ROS topics when asked, by subscribing briefly on the edge's Zenoh session."""

    def __init__(
        self,
        session: Callable[[], zenoh.Session | None],
        domain_id: int,
        decode: Callable[[bytes, str], Any],
        *,
        wait_s: float = 1.5,
        clock: Callable[[], float] = time.time,
    ) -> None:
        self._session = session
        self.domain_id = domain_id
        self._decode = decode
        self.wait_s = wait_s
        self._clock = clock

    def read(self, topics: Sequence[str]) -> dict[str, dict[str, Any]]:
        """``{topic: {"type", "value", "at", "link"}}`` for topics that published within ``wait_s``
        (``{"error": ...}`` for a sample that does not decode; missing: nothing came)."""
        session = self._session()
        if session is None or not topics:
            return {}
        got: dict[str, tuple[str, bytes, float]] = {}
        done = threading.Event()
        lock = threading.Lock()
        wanted = set(topics)

        def on_sample(sample: zenoh.Sample) -> None:
            try:
                key = parse_data_key(str(sample.key_expr))
            except Exception:  # noqa: BLE001 - a key that is not a ROS data key: not ours
                return
            with lock:
                if key.topic in wanted and key.topic not in got:
                    got[key.topic] = (key.ros_type, sample.payload.to_bytes(), self._clock())
                    if len(got) == len(wanted):
                        done.set()

        subscribers = [
            session.declare_subscriber(data_key_expr(self.domain_id, topic), on_sample) for topic in wanted
        ]
        try:
            done.wait(self.wait_s)
        finally:
            for sub in subscribers:
                sub.undeclare()
        out: dict[str, dict[str, Any]] = {}
        with lock:
            taken = dict(got)
        for topic, (typename, payload, at) in sorted(taken.items()):
            try:
                message = self._decode(payload, typename)
                value = plain(message)
            except Exception as exc:  # noqa: BLE001 - shown to the operator, not raised
                out[topic] = {"type": typename, "error": f"does not decode: {exc}", "at": at}
                continue
            out[topic] = {"type": typename, "value": value, "at": at, "link": link_of(value)}
            picture = picture_of(typename, message)
            if picture is not None:
                out[topic]["picture"] = picture
        return out
