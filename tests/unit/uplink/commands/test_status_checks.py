"""Status batches speak for the site of their key, about that site's robots only."""

from __future__ import annotations

from fleetlink.uplink.commands.ownership import Owner
from fleetlink.uplink.commands.status_checks import check_status
from fleetlink.wire.commands import StatusBatch, StatusEvent

OWNERS = {"tb4_01": Owner("site-a", True, 0), "tb4_09": Owner("site-b", True, 0)}


def event(robot: str, site: str = "") -> StatusEvent:
    return StatusEvent("c1", robot, "/x", "delivered", 1, site)


def test_events_carry_the_keys_site_and_foreign_robots_are_dropped() -> None:
    batch = StatusBatch("rep", "site-b", (event("tb4_09", "site-a"), event("tb4_01"), event("new")))
    checked = check_status("fleetlink/site-b/command-status/rep", batch, OWNERS.get)
    assert checked.problem is None
    assert [(e.robot, e.site) for e in checked.events] == [("tb4_09", "site-b"), ("new", "site-b")]
    assert checked.dropped == 1


def test_a_batch_naming_another_site_is_refused() -> None:
    batch = StatusBatch("rep", "site-a", (event("tb4_01"),))
    checked = check_status("fleetlink/site-b/command-status/rep", batch, OWNERS.get)
    assert checked.problem is not None
    assert "says site 'site-a'" in checked.problem
    assert checked.events == []
