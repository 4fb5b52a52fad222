"""Where a site may write: the cloud decides, per site and per Kafka topic (pure: no I/O).

Every topic a batch names gets one of four routes, decided once per (site, topic) and cached:

* ``produce``: a data topic the site's ``policy`` patterns allow; records go out as they are;
* ``registration``: the registrations topic; each record is decoded, checked and written anew
  by the uplink (``uplink.registration_records``);
* ``dead_letter``: the dead-letter topic; the edge's dead letters are written anew by the
  uplink with the sender headers it checked;
* ``refuse``: anything else; the records go to the refused topic with site, topic and reason.

Topics fleetlink owns are never ``produce``: those of the ``topics`` section (command status,
command dead letters, refused records, ...), the ``from`` topic of every command mapping (a
site must not command robots), every name starting with ``fleetlink.`` and every name starting
with ``_`` (Kafka's and the registry's own: ``__consumer_offsets``, ``_schemas``).
"""

from __future__ import annotations

import fnmatch
import re
import threading
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from typing import Literal

Route = Literal["produce", "registration", "dead_letter", "refuse"]

RESERVED_PREFIXES: tuple[str, ...] = ("fleetlink.", "_")
"""Topic name prefixes no site may write to (fleetlink's own namespace, Kafka's and the registry's)."""
SITE_PLACEHOLDER = "{site}"


@dataclass(frozen=True, slots=True)
class Decision:
    """Where records of one topic go (``route``), and why, when they are refused (``reason``)."""

    route: Route
    reason: str = ""


PRODUCE = Decision("produce")


@dataclass(frozen=True, slots=True)
class InternalTopics:
    """The topics fleetlink itself writes (from the uplink's config)."""

    registrations: str
    dead_letter: str
    owned: frozenset[str]
    """Every other topic only the uplink writes: command status and dead letters, refused
    records, the command mappings' source topics."""


class TopicPolicy:
    """``decide(site, topic)``: thread-safe; a decision is computed once per (site, topic)."""

    def __init__(
        self,
        patterns: Mapping[str, Sequence[str]],
        default: Sequence[str],
        internal: InternalTopics,
        *,
        max_cached: int = 100_000,
    ) -> None:
        self._patterns = {site: _compile(site, p) for site, p in patterns.items()}
        self._default = tuple(default)
        self._internal = internal
        self._cache: dict[tuple[str, str], Decision] = {}
        self._max_cached = max_cached
        self._lock = threading.Lock()

    def decide(self, site: str, topic: str) -> Decision:
        """The route of records from ``site`` for ``topic``, decided once and cached."""
        key = (site, topic)
        found = self._cache.get(key)
        if found is not None:
            return found
        decision = self._decide(site, topic)
        with self._lock:
            if len(self._cache) >= self._max_cached:
                self._cache.clear()
            self._cache[key] = decision
        return decision

    def routes(self, site: str, topics: Iterable[str]) -> dict[str, Decision]:
        """The decisions for ``topics`` that are not a plain ``produce`` (empty: all are)."""
        out: dict[str, Decision] = {}
        for topic in topics:
            decision = self.decide(site, topic)
            if decision is not PRODUCE:
                out[topic] = decision
        return out

    def _decide(self, site: str, topic: str) -> Decision:
        internal = self._internal
        if topic == internal.registrations:
            return Decision("registration")
        if topic == internal.dead_letter:
            return Decision("dead_letter")
        if topic in internal.owned or topic.startswith(RESERVED_PREFIXES):
            return Decision("refuse", f"topic {topic!r} is fleetlink's own: only the uplink writes it")
        compiled = self._patterns.get(site)
        if compiled is None:
            compiled = _compile(site, self._default)
        if any(pattern.fullmatch(topic) for pattern in compiled):
            return PRODUCE
        return Decision("refuse", f"site {site!r} may not write to topic {topic!r} (policy)")


def _compile(site: str, patterns: Sequence[str]) -> tuple[re.Pattern[str], ...]:
    return tuple(re.compile(fnmatch.translate(p.replace(SITE_PLACEHOLDER, site))) for p in patterns)


_PATTERN = re.compile(r"[A-Za-z0-9._*?\[\]!-]+")


def pattern_problem(pattern: str) -> str | None:
    """Why a topic pattern is unusable (None: it is fine). ``{site}`` stands for the site's name."""
    text = pattern.replace(SITE_PLACEHOLDER, "site")
    if not text or _PATTERN.fullmatch(text) is None:
        return "is not a topic pattern: Kafka topic characters, '*', '?', '[...]' and {site}"
    return None
