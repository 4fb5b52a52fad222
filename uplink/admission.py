"""Whether a decoded batch may be produced, checked once per batch before any record is touched.

In order: the sender (the key's site and edge) against the batch's own site and edge and its
records' sender headers (``identity``); every schema text it carries against its fingerprint,
learnt for that site only (``schema_ids``); then one policy decision per distinct Kafka topic
(``policy``). The first two refuse the whole batch; the topics decide where each record goes.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

from fleetlink.uplink.identity import Source, header_problem, identity_problem
from fleetlink.uplink.policy import Decision, TopicPolicy
from fleetlink.uplink.schema_ids import SchemaIds
from fleetlink.wire import Batch


@dataclass(frozen=True, slots=True)
class Refused:
    """A batch refused whole: which check failed (``reason``) and what was wrong (``detail``)."""

    reason: str
    """``identity``, ``headers`` or ``schema`` (a metric label)."""
    detail: str


@dataclass(frozen=True, slots=True)
class Admitted:
    """A batch that may be produced: its checked sender and the routes of its diverted topics."""

    source: Source
    routes: Mapping[str, Decision]
    """The batch's topics whose records do not go out as they are (empty: none)."""


class Admission:
    """Checks each decoded batch before any record is produced: sender, schema texts, then the topic
    policy."""

    def __init__(self, policy: TopicPolicy, ids: SchemaIds) -> None:
        self._policy = policy
        self._ids = ids

    def check(self, source: Source, batch: Batch) -> Admitted | Refused:
        """Admit ``batch`` from ``source`` with its topics' routes, or refuse it at the first check that
        fails (schema texts that match are learnt on the way)."""
        problem = identity_problem(source, batch)
        if problem is not None:
            return Refused("identity", problem)
        problem = header_problem(source, batch.records)
        if problem is not None:
            return Refused("headers", problem)
        if batch.schemas:
            wrong = self._ids.learn(source.site, batch.schemas)
            if wrong:
                names = ", ".join(fp.hex() for fp in wrong)
                return Refused("schema", f"schema text(s) do not match their fingerprint: {names}")
        topics = {record.kafka_topic for record in batch.records}
        return Admitted(source, self._policy.routes(source.site, topics))
