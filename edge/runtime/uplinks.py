"""Which uplink takes a stream's batches: several uplinks share a fleet's load.

Every uplink serves the ingest keys (``fleetlink/<site>/ingest/<edge_id>``, one of them takes a
query) and, under its own id, ``.../via/<uplink id>``. The edge learns the ids by probing
``.../via/*`` (every uplink answers on its own key) at most every ``probe_every_s`` while it
sends, and sends each stream's batches to one of them, chosen by rendezvous hashing of the
edge's key and the stream over the ids: the edges of a fleet spread over the uplinks, one
stream keeps its uplink (its batches stay in order, an exactly-once stream keeps its
transactional producer), and when an uplink leaves only its streams move. An uplink that does
not answer a batch is left out until a probe finds it again; with none known, batches go to
the ingest key itself (Zenoh picks an uplink), as with uplinks that serve no ``via`` key.
"""

from __future__ import annotations

import contextlib
import hashlib
import threading
import time
from collections.abc import Callable, Collection

import zenoh

from fleetlink.wire.keys import via_key

PROBE_EVERY_S = 2.0


def pick(route: str, uplinks: Collection[str]) -> str | None:
    """The uplink that takes ``route`` (rendezvous hashing: the highest score wins; None: no uplink)."""
    best: tuple[bytes, str] | None = None
    for uplink in uplinks:
        score = hashlib.blake2b(f"{route}|{uplink}".encode(), digest_size=8).digest()
        if best is None or (score, uplink) > best:
            best = (score, uplink)
    return best[1] if best is not None else None


class Uplinks:
    """The uplinks serving one ingest key, as the last probe found them, less those that failed since."""

    def __init__(
        self,
        session: zenoh.Session,
        key: str,
        *,
        probe_every_s: float = PROBE_EVERY_S,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        self._session = session
        self._key = key
        self._probe_every_s = probe_every_s
        self._clock = clock
        self._lock = threading.Lock()
        self._live: frozenset[str] = frozenset()
        self._probed_at: float | None = None
        self.probes = 0

    def route(self, route: str) -> str | None:
        """The id of the uplink that takes ``route``'s batches now (None: send to the ingest key);
        starts a probe first when the last one is ``probe_every_s`` old."""
        now = self._clock()
        with self._lock:
            due = self._probed_at is None or now - self._probed_at >= self._probe_every_s
            if due:
                self._probed_at = now
            live = self._live
        if due:
            self._probe()
        return pick(f"{self._key}|{route}", live)

    def failed(self, uplink: str) -> None:
        """``uplink`` did not answer a batch: leave it out until a probe finds it again."""
        with self._lock:
            self._live = self._live - {uplink}

    def live(self) -> frozenset[str]:
        """The uplinks batches go to now."""
        with self._lock:
            return self._live

    def _probe(self) -> None:
        seen: set[str] = set()
        prefix = via_key(self._key, "")

        def on_reply(reply: zenoh.Reply) -> None:
            if reply.ok is not None:
                key = str(reply.ok.key_expr)
                if key.startswith(prefix) and "/" not in key[len(prefix) :]:
                    seen.add(key[len(prefix) :])

        def on_finished() -> None:
            with self._lock:
                self._live = frozenset(seen)
            self.probes += 1

        # a closing session refuses the probe: the send that follows says why
        with contextlib.suppress(zenoh.ZError):
            self._session.get(
                via_key(self._key, "*"),
                zenoh.handlers.Callback(on_reply, on_finished, indirect=False),
                target=zenoh.QueryTarget.ALL,
                timeout=self._probe_every_s,
            )
