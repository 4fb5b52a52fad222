"""A restart: the journal's commands whose lease still holds are resumed, the others reported."""

from __future__ import annotations

import logging
from collections.abc import Callable

from fleetlink.repeater.schedule import Change, Offer
from fleetlink.repeater.shared import Shared, to_command
from fleetlink.repeater.statuses import record
from fleetlink.wire.commands import CommandEnvelope

log = logging.getLogger(__name__)

Check = Callable[[CommandEnvelope, str | None], str]
"""Converts a command for its repeats; the reason it cannot be, or '' (``Intake.check``)."""


def restore(shared: Shared, check: Check) -> None:
    """Resume the commands of the journal whose lease holds; report the others expired (under the lock).

    What is due at once waits in ``shared.initial`` until the publish loop runs.
    """
    now = shared.clock()
    for ident, stored in list(shared.store.commands.items()):
        env, command = stored.envelope, to_command(stored.envelope)
        if stored.ended:
            shared.schedule.remember(command)
            continue
        problem = check(env, shared.store.schemas.get(env.schema_fp))
        if problem:
            shared.schedule.remember(command)
            record(shared, [Change(command, "rejected", now, f"after restart: {problem}")])
            continue
        outcome = shared.schedule.offer(
            command, now, delivered=stored.delivered, received_at=stored.received_at
        )
        changes = outcome.changes
        if outcome.offer is Offer.EXPIRED:
            changes = [Change(command, "expired", now, "lease ended while the repeater was down")]
        record(shared, changes)
        shared.initial += outcome.publish
        log.debug("restored command %s: %s", ident, outcome.offer.value)
    shared.store.maybe_compact(now, force=True)
