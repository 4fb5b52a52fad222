"""Find out which rmw_zenoh wire variant a network speaks, before publishing into it.

A sender must not pick the attachment layout blindly (rmw_zenoh.md §4, §11): a 77-byte (v1)
attachment means an rmw_zenoh from before mid-2025, a 33-byte one (v2) a current one; endpoint
tokens whose hash chunk is ``TypeHashNotSupported`` come from Humble. :class:`WireTally` counts
what it is shown (pure); :func:`probe_wire` listens to a live network for a while.
"""

from __future__ import annotations

import threading
import time
from collections import Counter
from dataclasses import dataclass
from typing import Literal

import zenoh

from fleetlink.roswire.attachment import AttachmentVersion, detect_version
from fleetlink.roswire.errors import TokenError
from fleetlink.roswire.names import HASH_NOT_SUPPORTED
from fleetlink.roswire.tokens import EndpointInfo, liveliness_prefix, parse_token

HashStyle = Literal["humble", "rihs01"]


@dataclass(frozen=True)
class WireVerdict:
    """Which wire variant a network speaks, and the counts it was decided from."""

    attachment_version: AttachmentVersion | None
    """The layout seen on most samples, None when no sample carried a known one."""
    hash_style: HashStyle | None
    """``humble`` when endpoint tokens say TypeHashNotSupported, ``rihs01`` when they carry hashes."""
    attachments: dict[str, int]
    endpoints: int

    @property
    def mixed(self) -> bool:
        """Whether both v1 and v2 attachments were seen."""
        return self.attachments.get("v1", 0) > 0 and self.attachments.get("v2", 0) > 0


class WireTally:
    """Counts attachment layouts and hash styles seen; not thread-safe."""

    def __init__(self) -> None:
        self.attachments: Counter[str] = Counter()
        self.hashes: Counter[str] = Counter()

    def observe_attachment(self, raw: bytes | None) -> None:
        """Count one sample's attachment by layout (``v1``, ``v2``, ``unknown``, or ``none`` when absent)."""
        if raw is None:
            self.attachments["none"] += 1
            return
        version = detect_version(raw)
        self.attachments[f"v{version}" if version else "unknown"] += 1

    def observe_endpoint(self, endpoint: EndpointInfo) -> None:
        """Count one endpoint token's hash style (Humble's TypeHashNotSupported or RIHS01)."""
        self.hashes["humble" if endpoint.type_hash == HASH_NOT_SUPPORTED else "rihs01"] += 1

    def verdict(self) -> WireVerdict:
        """The variant most of what was seen speaks (v2 and RIHS01 on a tie); None where nothing was seen."""
        v1, v2 = self.attachments.get("v1", 0), self.attachments.get("v2", 0)
        version: AttachmentVersion | None = None
        if v1 or v2:
            version = 2 if v2 >= v1 else 1
        style: HashStyle | None = None
        if self.hashes:
            style = "humble" if self.hashes["humble"] > self.hashes["rihs01"] else "rihs01"
        return WireVerdict(version, style, dict(self.attachments), sum(self.hashes.values()))


def probe_wire(session: zenoh.Session, domain: int, seconds: float = 2.0) -> WireVerdict:
    """Listen to ``<domain>/**`` and the domain's tokens (present ones included) for ``seconds``."""
    tally = WireTally()
    lock = threading.Lock()
    seen: set[str] = set()

    def on_sample(sample: zenoh.Sample) -> None:
        att = sample.attachment
        with lock:
            tally.observe_attachment(att.to_bytes() if att is not None else None)

    def on_token(sample: zenoh.Sample) -> None:
        key = str(sample.key_expr)
        if sample.kind != zenoh.SampleKind.PUT or key in seen:
            return
        try:
            entity = parse_token(key)
        except TokenError:
            return
        if isinstance(entity, EndpointInfo):
            with lock:
                seen.add(key)
                tally.observe_endpoint(entity)

    data = session.declare_subscriber(f"{domain}/**", on_sample)
    tokens = session.liveliness().declare_subscriber(liveliness_prefix(domain), on_token, history=True)
    try:
        time.sleep(seconds)
    finally:
        tokens.undeclare()
        data.undeclare()
    with lock:
        return tally.verdict()
