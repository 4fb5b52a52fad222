"""Which uplink takes a stream: rendezvous hashing over the uplinks a probe found."""

from __future__ import annotations

from fleetlink.edge.runtime.uplinks import pick


def test_no_uplink_means_the_ingest_key() -> None:
    assert pick("fleetlink/s/ingest/e|at_least_once", []) is None


def test_the_choice_does_not_depend_on_the_order_uplinks_were_found_in() -> None:
    uplinks = ["up-a", "up-b", "up-c"]
    for n in range(50):
        route = f"fleetlink/site-{n}/ingest/edge-1|at_least_once"
        assert pick(route, uplinks) == pick(route, list(reversed(uplinks))) in uplinks


def test_streams_spread_over_the_uplinks() -> None:
    routes = [f"fleetlink/site-{n}/ingest/edge-1|at_least_once" for n in range(200)]
    chosen = [pick(r, ["up-a", "up-b"]) for r in routes]
    assert 60 <= chosen.count("up-a") <= 140  # about half each (a fixed hash: the count is fixed too)
    assert chosen.count("up-a") + chosen.count("up-b") == 200


def test_only_the_streams_of_an_uplink_that_leaves_move() -> None:
    routes = [f"fleetlink/site-{n}/ingest/edge-1|at_least_once" for n in range(200)]
    before = {r: pick(r, ["up-a", "up-b", "up-c"]) for r in routes}
    after = {r: pick(r, ["up-a", "up-c"]) for r in routes}
    moved = [r for r in routes if before[r] != after[r]]
    assert moved
    assert all(before[r] == "up-b" for r in moved)
    assert all(after[r] == before[r] for r in routes if before[r] != "up-b")
