"""The sender of a batch is the key it came on; the body and the sender headers must agree."""

from __future__ import annotations

import pytest

from fleetlink.uplink.identity import Source, header_problem, identity_problem, source_of
from fleetlink.wire import Batch, Record

SOURCE = Source("site-b", "edge-b")


def batch(site: str = "site-b", edge: str = "edge-b", headers: tuple[tuple[str, bytes], ...] = ()) -> Batch:
    records = (
        Record("fleet.x", b"r1", b"v", (("fleetlink.site", b"site-b"), ("fleetlink.edge", b"edge-b")), 0, 1),
        Record("fleet.x", b"r2", b"v", headers, 0, 2),
    )
    return Batch(site, edge, "durable", 1, records)


@pytest.mark.parametrize(
    ("key", "source"),
    [
        ("fleetlink/site-b/ingest/edge-b", SOURCE),
        ("fleetlink/site-b/ingest", None),
        ("fleetlink/site-b/events/edge-b", None),
        ("other/site-b/ingest/edge-b", None),
        ("fleetlink/*/ingest/edge-b", None),
        ("fleetlink/site-b/ingest/edge b", None),
    ],
)
def test_source_of(key: str, source: Source | None) -> None:
    assert source_of(key) == source


def test_a_batch_that_names_another_site_or_edge_is_refused() -> None:
    assert identity_problem(SOURCE, batch()) is None
    assert "says site 'site-a'" in (identity_problem(SOURCE, batch(site="site-a")) or "")
    assert "says edge 'edge-a'" in (identity_problem(SOURCE, batch(edge="edge-a")) or "")


@pytest.mark.parametrize(
    ("headers", "problem"),
    [
        ((), None),
        ((("fleetlink.robot", b"tb4_01"), ("fleetlink.seq", b"7")), None),
        ((("fleetlink.site", b"site-b"),), None),
        ((("fleetlink.site", b"site-a"),), "fleetlink.site='site-a'"),
        ((("fleetlink.edge", b"edge-a"),), "fleetlink.edge='edge-a'"),
        ((("fleetlink.site", b"site-b"), ("fleetlink.site", b"site-a")), "fleetlink.site='site-a'"),
    ],
)
def test_sender_headers_must_name_the_sender(
    headers: tuple[tuple[str, bytes], ...], problem: str | None
) -> None:
    found = header_problem(SOURCE, batch(headers=headers).records)
    if problem is None:
        assert found is None
    else:
        assert found is not None
        assert problem in found
        assert "record 2" in found
