"""Status changes of commands: journalled, sent to the uplink over the status link, logged."""

from __future__ import annotations

import logging

from fleetlink.repeater.schedule import Change
from fleetlink.repeater.shared import Shared
from fleetlink.wire.commands import StatusEvent

log = logging.getLogger(__name__)

_FINAL = frozenset({"superseded", "expired", "rejected"})


def record(shared: Shared, changes: list[Change]) -> None:
    """Journal each change, release what a final one ends, and queue it for the uplink (under the lock)."""
    for change in changes:
        cmd = change.command
        ident = cmd.ident
        event = StatusEvent(
            cmd.command_id,
            cmd.robot,
            cmd.ros_topic,
            change.status,
            int(change.at * 1000),
            shared.site,
            change.detail,
        )
        if change.status in _FINAL:
            shared.store.mark(ident, "end")
            shared.cdr.pop(ident, None)
            if shared.publishers is not None and cmd.ros_topic not in shared.schedule.topics():
                shared.publishers.release(cmd.ros_topic, change.at)
        elif change.status == "delivered":
            shared.store.mark(ident, "delivered")
        number = shared.store.status(event)
        if shared.link is not None:
            shared.link.submit(number, event)
        log.info(
            "command %s robot=%s topic=%s: %s (%s)",
            cmd.command_id,
            cmd.robot,
            cmd.ros_topic,
            change.status,
            change.detail,
        )
