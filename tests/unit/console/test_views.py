"""fleetlink.console.views: one site's page data from the admin answers; fleet summaries."""

from __future__ import annotations

from typing import Any

from fleetlink.console.envelope import Envelope, failure
from fleetlink.console.rates import RateBoard
from fleetlink.console.views import site_summary, site_view


def ok(body: Any) -> Envelope:
    return Envelope(status=200, site="s", edge_id="edge-1", body=body)


def mapping(received: int, emitted: int, dropped: int = 0, mismatch: int = 0) -> dict[str, Any]:
    return {
        "name": "ir",
        "robot_type": "tb4",
        "to": "fleet.ir",
        "issues": [],
        "counters": {
            "received": received,
            "emitted": emitted,
            "dropped": dropped,
            "dead_lettered": 0,
            "type_mismatch": mismatch,
        },
    }


def parts(received: int, emitted: int, dropped: int, topic_received: int) -> dict[str, Envelope]:
    return {
        "robots": ok([{"robot": "tb4_01", "robot_type": "tb4", "state": "registered"}]),
        "topics": ok(
            [
                {
                    "topic": "/tb4_01/ir",
                    "types": ["t"],
                    "publishers": [{"node": "n"}],
                    "mappings": [{"mapping": "ir", "robot": "tb4_01", "kafka_topic": "fleet.ir"}],
                }
            ]
        ),
        "mappings": ok([mapping(received, emitted, dropped, mismatch=1)]),
        "robot_types": ok([{"name": "tb4"}, {"nameless": True}]),
        "health": ok({"state": "ok", "robots": 1}),
        "status": ok({"topics": {"/tb4_01/ir": {"received": topic_received}}}),
    }


def test_rates_come_from_counter_changes_between_polls() -> None:
    board = RateBoard()
    first = site_view("s", parts(0, 0, 0, 0), board, now=100.0)
    assert first["mappings"][0]["rates"] == {
        "received": None,
        "emitted": None,
        "filtered": None,
        "dropped": None,
        "dead_lettered": None,
    }
    assert first["topic_rates"] == {"/tb4_01/ir": None}
    second = site_view("s", parts(20, 4, 15, 22), board, now=102.0)
    assert second["mappings"][0]["rates"] == {
        "received": 10.0,
        "emitted": 2.0,
        "filtered": 0.0,
        "dropped": 7.5,
        "dead_lettered": 0.0,
    }  # dropped counts type mismatches too
    assert second["topic_rates"] == {"/tb4_01/ir": 11.0}
    assert second["graph"]["topics"][0]["rate"] == 11.0
    assert second["graph"]["kafka"] == [
        {"id": "k:fleet.ir", "label": "fleet.ir", "rate": None, "mapped": 2.0, "approx": False}
    ]  # no uplink figures given: what Kafka acknowledged is not known
    assert (second["site"], second["edge_id"], second["at"], second["errors"]) == ("s", "edge-1", 102.0, {})
    assert second["robot_types"] == ["tb4"]
    assert second["health"] == {"state": "ok", "robots": 1}


def test_parts_that_fail_or_are_missing_are_named() -> None:
    answers = parts(0, 0, 0, 0)
    answers["topics"] = failure(401, "missing or wrong admin token")
    del answers["status"]
    answers["health"] = Envelope(status=503, site="s", edge_id="edge-1", body={"state": "failed"})
    view = site_view("s", answers, RateBoard(), now=1.0)
    assert view["errors"] == {
        "topics": "401: missing or wrong admin token",
        "status": "not reported by this site",
    }
    assert view["health"] == {"state": "failed"}  # a failed site's health still shows
    assert view["status"] is None
    assert view["graph"]["topics"] == []
    assert [m["name"] for m in view["mappings"]] == ["ir"]


def test_a_site_that_does_not_answer() -> None:
    view = site_view(
        "s", {"health": failure(504, "no edge of site 's' answered within 3 s")}, RateBoard(), now=1.0
    )
    assert view["errors"]["health"] == "504: no edge of site 's' answered within 3 s"
    assert set(view["errors"]) == {"robots", "topics", "mappings", "robot_types", "health", "status"}
    assert (view["health"], view["robots"], view["edge_id"]) == (None, [], "")


def test_site_summaries() -> None:
    body = {"state": "degraded", "robots": 3, "wan_link_up": False, "problems": [{}, {}]}
    assert site_summary("a", Envelope(status=200, site="a", edge_id="e", body=body)) == {
        "site": "a",
        "edge_id": "e",
        "status": 200,
        "state": "degraded",
        "robots": 3,
        "wan_link_up": False,
        "problems": 2,
        "error": None,
    }
    refused = site_summary("b", failure(401, "missing or wrong admin token", site="b"))
    assert (refused["state"], refused["error"], refused["problems"]) == (
        None,
        "missing or wrong admin token",
        None,
    )


def test_intended_drops_are_told_apart_from_losses() -> None:
    board = RateBoard()
    for now, (received, dropped, throttled, errors) in ((100.0, (0, 0, 0, 0)), (102.0, (40, 36, 30, 2))):
        body = mapping(received, received - dropped, dropped, mismatch=0)
        body["stage_counters"] = [{"name": "throttle", "dropped": throttled, "late": 0, "errors": errors}]
        answers = parts(0, 0, 0, 0) | {"mappings": ok([body])}
        view = site_view("s", answers, board, now=now)
    rates = view["mappings"][0]["rates"]
    assert (rates["filtered"], rates["dropped"]) == (15.0, 3.0)  # the throttle's, then the rest


def test_the_kafka_column_shows_what_every_uplink_acknowledged() -> None:
    board = RateBoard()

    def answer(uplink: str, acked: int) -> dict[str, object]:
        return {
            "uplink": uplink,
            "site": "s",
            "batches": {"ok": 1},
            "records": acked,
            "topics": {"fleet.ir": acked},
        }

    site_view("s", parts(0, 0, 0, 0), board, now=100.0, delivery=[answer("u1", 0), answer("u2", 0)])
    view = site_view("s", parts(20, 4, 15, 22), board, now=102.0, delivery=[answer("u1", 6), answer("u2", 2)])
    assert [(n["rate"], n["mapped"]) for n in view["graph"]["kafka"]] == [(4.0, 2.0)]
    outage = site_view("s", parts(40, 8, 30, 44), board, now=104.0, delivery=[])
    assert [(n["rate"], n["mapped"]) for n in outage["graph"]["kafka"]] == [(0.0, 2.0)]
