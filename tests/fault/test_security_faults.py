"""Rows 30-36 of the fault matrix: a rogue site against real routers, uplink, Kafka and registry.

The rogue (``tests.fault.rogue_site``) is a separate process holding only site B's keys: site
B's edge certificate, straight to the cloud router, or a client on site B's network. Each test
asserts that nothing forged reached Kafka or a robot, that the refusal was counted, and that
site A, streaming all along, lost nothing (docs/guarantees.md).
"""

from __future__ import annotations

import json
import os
import socket
import urllib.request
from collections.abc import Collection, Iterator
from pathlib import Path

import pytest
import yaml
from confluent_kafka import Message
from confluent_kafka.admin import AdminClient
from confluent_kafka.schema_registry import SchemaRegistryClient

from fleetlink.localstack.process import free_port
from tests.fault.e2e_processes import Process
from tests.fault.security_bed import SecurityBed, edge_yaml, security_bed
from tests.helpers import wait_until
from tests.integration.e2e_stack import headers
from tests.integration.test_commands_harness import GREEN, RED
from tests.integration.zenoh_topology import client_config, opened

pytestmark = pytest.mark.timeout(600)

FORGED = b"forged"


@pytest.fixture(scope="module")
def bed(
    tmp_path_factory: pytest.TempPathFactory, kafka_bootstrap: str, schema_registry_url: str
) -> Iterator[SecurityBed]:
    with security_bed(tmp_path_factory.mktemp("security"), kafka_bootstrap, schema_registry_url) as b:
        yield b


def only_answer(result: dict[str, object]) -> dict[str, object]:
    answers = result["answers"]
    assert isinstance(answers, list), result
    assert len(answers) == 1, result
    answer = answers[0]
    assert isinstance(answer, dict)
    return answer


def failures(answer: dict[str, object]) -> list[str]:
    reasons = answer["failures"]
    assert isinstance(reasons, list)
    return [str(r) for r in reasons]


def existing_topics(bed: SecurityBed) -> set[str]:
    return set(AdminClient({"bootstrap.servers": bed.bootstrap}).list_topics(timeout=10).topics)


def forged_in(bed: SecurityBed, topic: str) -> int:
    """Records of ``topic`` (if it exists) whose value carries the rogue's marker."""
    if topic not in existing_topics(bed):
        return 0
    msgs = bed.reader.consume(topic, 0, lambda ms: False, 2.0)
    return sum(FORGED in (m.value() or b"") for m in msgs)


def refused_for(bed: SecurityBed, topics: Collection[str], count: int) -> list[dict[str, str]]:
    """The headers of the refused topic's records about ``topics`` (other tests' are skipped):
    read until ``count`` are there, and a second more to show no more follow."""

    def about(msgs: list[Message]) -> list[dict[str, str]]:
        return [h for h in map(headers, msgs) if h.get("fleetlink.dlq.topic") in topics]

    refused = bed.topics.refused
    msgs = bed.reader.read_until(refused, lambda ms: len(about(ms)) >= count, 30, what=f"{count} refused")
    return about(msgs + bed.reader.consume(refused, len(msgs), lambda ms: False, 1.0))


def assert_site_a_kept_flowing(bed: SecurityBed) -> None:
    result = bed.honest_site_kept_flowing()
    assert result.lost == [], f"site A lost records: {result}"
    assert result.unexpected == 0, f"something forged reached site A's topic: {result}"


# -- row 30 -------------------------------------------------------------------------------------


def test_row30_a_batch_claiming_another_site_is_refused_whole(bed: SecurityBed) -> None:
    result = bed.rogue("forged-site", a_topic=bed.topics.chat)
    claims = only_answer(result["claims_site_a"])
    assert "refused (identity)" in str(claims.get("error")), claims
    forged_headers = only_answer(result["forged_headers"])
    assert "refused (headers)" in str(forged_headers.get("error")), forged_headers
    assert result["site_a_key"]["answers"] == []  # the cloud's ACL: site B cannot query site A's keys
    assert bed.counter("fleetlink_ingest_refused_batches_total", site="site-b", reason="identity") >= 1
    assert bed.counter("fleetlink_ingest_refused_batches_total", site="site-b", reason="headers") >= 1
    assert_site_a_kept_flowing(bed)  # nothing of the forged batches in site A's topic
    assert forged_in(bed, bed.topics.registrations) == 0


# -- row 31 -------------------------------------------------------------------------------------


def test_row31_a_record_for_a_topic_outside_the_sites_policy_goes_to_the_refused_topic(
    bed: SecurityBed,
) -> None:
    t = bed.topics
    foreign = (t.a_private, t.other)
    result = bed.rogue("foreign-topic", foreign_topics=list(foreign), b_topic=t.b_own)
    answer = only_answer(result["foreign"])
    assert (answer["status"], answer["dead_lettered"]) == ("ok", 2), answer
    refused = refused_for(bed, foreign, 2)
    assert sorted(h["fleetlink.dlq.topic"] for h in refused) == sorted(foreign)
    assert {(h["fleetlink.site"], h["fleetlink.dlq.stage"]) for h in refused} == {("site-b", "topic")}
    assert all("policy" in h["fleetlink.dlq.reason"] for h in refused)
    assert not {t.a_private, t.other} & existing_topics(bed)  # never produced, never created
    own = bed.reader.read(t.b_own, 1)  # where site B may write, it does
    assert [headers(m)["fleetlink.site"] for m in own] == ["site-b"]
    assert bed.counter("fleetlink_ingest_refused_records_total", site="site-b", reason="topic") >= 2
    assert_site_a_kept_flowing(bed)


# -- row 32 -------------------------------------------------------------------------------------


def test_row32_a_site_cannot_write_into_fleetlinks_own_topics(bed: SecurityBed) -> None:
    t = bed.topics
    internal = t.owned_by_fleetlink()
    topics_before = existing_topics(bed)
    refused_before = bed.counter("fleetlink_ingest_refused_records_total", site="site-b", reason="topic")
    result = bed.rogue("internal-topic", internal_topics=internal)
    answer = only_answer(result["internal"])
    assert (answer["status"], answer["dead_lettered"]) == ("ok", len(internal)), answer
    assert all("fleetlink's own" in reason for reason in failures(answer))
    for topic in internal:
        if topic != t.refused:
            assert forged_in(bed, topic) == 0, topic
    # the refused topic holds the uplink's records about them, never the rogue's own record
    refused = refused_for(bed, internal, len(internal))
    assert len(refused) == len(internal)
    assert {h["fleetlink.site"] for h in refused} == {"site-b"}
    assert not ({f"fleetlink.{t.run}.x", f"_{t.run}.x"} & (existing_topics(bed) - topics_before))
    after = bed.counter("fleetlink_ingest_refused_records_total", site="site-b", reason="topic")
    assert after - refused_before == len(internal)
    assert bed.leds_a.count("tb4_01") == bed.leds_b.count("tb4_01") == 0  # no command came of it
    assert_site_a_kept_flowing(bed)


# -- row 33 -------------------------------------------------------------------------------------


def test_row33_a_robot_another_site_holds_cannot_be_claimed(bed: SecurityBed) -> None:
    t = bed.topics
    result = bed.rogue("forged-registration", registrations=t.registrations)
    answer = only_answer(result["claim"])
    assert (answer["status"], answer["dead_lettered"]) == ("ok", 2), answer
    assert all("site 'site-a'" in reason for reason in failures(answer))
    registrations = bed.reader.read(t.registrations, 1)  # site A's own registration, and any other
    for msg in registrations:
        value = bed.reader.value(msg)
        assert (msg.key(), value["site"], headers(msg)["fleetlink.site"]) == (b"tb4_01", "site-a", "site-a")
    assert bed.counter("fleetlink_ingest_refused_records_total", site="site-b", reason="registration") == 2
    # the next command for tb4_01 goes to site A's robot, and to nobody at site B
    applied_b = bed.repeater_b.stats.applied
    bed.commands.send(t.commands, "tb4_01", GREEN, command_id=f"green-{t.run}")
    bed.wait(lambda: bed.leds_a.first("tb4_01", "green") is not None, 20, "site A's tb4_01 turns green")
    assert bed.leds_b.count("tb4_01") == 0
    assert bed.repeater_b.stats.applied == applied_b
    assert_site_a_kept_flowing(bed)


# -- row 34 -------------------------------------------------------------------------------------


def test_row34_schema_texts_are_checked_against_their_fingerprint(bed: SecurityBed) -> None:
    t = bed.topics
    result = bed.rogue("schema-poisoning", b_topic=t.b_own)
    wrong = only_answer(result["wrong_text"])
    assert "refused (schema)" in str(wrong.get("error")), wrong
    lookalike = only_answer(result["lookalike"])
    assert lookalike["status"] == "ok", lookalike  # a matching text: site B's own, for its own topic
    assert bed.counter("fleetlink_ingest_refused_batches_total", site="site-b", reason="schema") >= 1
    assert_site_a_kept_flowing(bed)
    # every record of site A, the ones after the attack included, is under site A's own text
    registry = SchemaRegistryClient({"url": bed.registry_url})
    msgs = bed.reader.consume(t.chat, 0, lambda ms: False, 2.0)
    ids = {int.from_bytes((m.value() or b"")[1:5], "big") for m in msgs}
    for schema_id in ids:
        text = registry.get_schema(schema_id).schema_str or ""
        assert "forged" not in text, text
        assert '"long"' not in text, text
    for version in registry.get_versions(f"{t.chat}-value"):
        assert "forged" not in (registry.get_version(f"{t.chat}-value", version).schema.schema_str or "")


# -- row 35 -------------------------------------------------------------------------------------


def test_row35_a_command_the_cloud_did_not_sign_is_refused_and_never_journalled(bed: SecurityBed) -> None:
    t = bed.topics
    forged_before = bed.repeater_b.stats.forged
    leds_before = bed.leds_b.count("tb4_09")
    result = bed.rogue("forged-command", via="site-b", ready_key="fleetlink/site-b/command/tb4_09/lightring")
    assert "command refused (unsigned)" in str(only_answer(result["unsigned"]).get("error"))
    assert "command refused (unknown_key)" in str(only_answer(result["own_key"]).get("error"))
    assert result["site_a"]["answers"] == []  # site B's router does not let it reach site A
    assert bed.repeater_b.stats.forged - forged_before == 2
    assert bed.repeater_a.stats.forged == 0
    journal = b"".join(p.read_bytes() for p in (bed.tmp / "rep-b").rglob("*") if p.is_file())
    assert FORGED not in journal
    # a genuine command reaches the same robot through the same repeater, meanwhile
    bed.commands.send(t.commands, "tb4_09", RED, command_id=f"red-{t.run}")
    bed.wait(lambda: bed.leds_b.first("tb4_09", "red") is not None, 20, "tb4_09 turns red")
    assert {name for _t, name in bed.leds_b.of("tb4_09")[leds_before:]} == {"red"}  # nothing forged shown
    assert_site_a_kept_flowing(bed)


# -- row 36 -------------------------------------------------------------------------------------


def test_row36_an_open_admin_is_refused_at_start_and_guessing_tokens_is_slowed(
    bed: SecurityBed, tmp_path: Path
) -> None:
    t = bed.topics
    port = free_port()
    open_yaml = edge_yaml(
        tmp_path, t, bed.site_b.endpoint, "site-b", "edge-b", admin={"listen": f"0.0.0.0:{port}"}
    )
    _strip_robot_types(open_yaml)
    env = {k: v for k, v in os.environ.items() if not k.startswith("FLEETLINK_ADMIN_TOKEN")}
    refused = Process("edge-b-open", ["edge", "run", "-c", str(open_yaml)], tmp_path / "edge-b-open.log")
    refused.start(env)
    assert refused.proc is not None
    assert refused.proc.wait(60) == 1
    assert "admin.listen" in refused.tail()
    assert "0.0.0.0" in refused.tail()
    assert not _listening(port)

    # on loopback with a token: the rogue on site B's network guesses, over Zenoh and HTTP
    port = free_port()
    token = "edge-b-" + "k" * 24
    closed_yaml = edge_yaml(
        tmp_path, t, bed.site_b.endpoint, "site-b", "edge-b", admin={"listen": f"127.0.0.1:{port}"}
    )
    _strip_robot_types(closed_yaml)
    edge_b = Process("edge-b", ["edge", "run", "-c", str(closed_yaml)], tmp_path / "edge-b.log")
    bed.processes.append(edge_b.start({**env, "FLEETLINK_ADMIN_TOKEN": token}))
    try:
        result = bed.rogue(
            "open-admin",
            via="site-b",
            ready_key="fleetlink/site-b/admin/mappings",
            admin_url=f"http://127.0.0.1:{port}",
        )
        zenoh_statuses = [json.loads(a[0]["ok"])["status"] for a in result["zenoh"]]
        # five guesses are checked; after that only one per lockout (1 s, doubling) is
        for statuses, tries in ((zenoh_statuses, 20), (result["http"], 200)):
            assert len(statuses) == tries
            assert statuses[:5] == [401] * 5, statuses
            assert set(statuses) == {401, 429}, statuses
            assert statuses.count(401) <= 8, statuses
        mappings = _admin_with_token(bed, token)
        assert [m["name"] for m in mappings] == []
        metrics = _scrape(f"http://127.0.0.1:{port}/metrics")
        assert 'fleetlink_admin_refused_total{reason="locked_out"}' in metrics
        assert 'fleetlink_admin_refused_total{reason="wrong_token"}' in metrics
    finally:
        edge_b.terminate(10)
    assert_site_a_kept_flowing(bed)


def _strip_robot_types(path: Path) -> None:
    """Edge B maps nothing: it exists for its admin, not to register site B's robots."""
    data = yaml.safe_load(path.read_text())
    data["robot_types"] = {}
    data["spool"]["dir"] = str(path.parent / f"spool-{path.stem}")
    path.write_text(yaml.safe_dump(data))


def _listening(port: int) -> bool:
    with socket.socket() as s:
        return s.connect_ex(("127.0.0.1", port)) == 0


def _scrape(url: str) -> str:
    with urllib.request.urlopen(url, timeout=5) as response:
        return str(response.read().decode())


def _admin_with_token(bed: SecurityBed, token: str) -> list[dict[str, object]]:
    """Site B's mappings, asked over Zenoh with the right token once the lockout is over."""
    answer: list[dict[str, object]] = []
    with opened(client_config(bed.site_b.endpoint)) as session:

        def asked() -> bool:
            for reply in session.get(
                "fleetlink/site-b/admin/mappings", attachment=f"Bearer {token}".encode(), timeout=3.0
            ):
                if reply.ok is not None:
                    envelope = json.loads(reply.ok.payload.to_bytes())
                    if envelope["status"] == 200:
                        answer[:] = envelope["body"]
                        return True
            return False

        wait_until(
            asked, 30, interval=0.5, message="site B's admin answers the right token after the lockout"
        )
    return answer
