"""Leases at work: a late joiner still gets the command, nothing is published after the lease,
a newer command supersedes an older one, and each case leaves its status records in Kafka."""

from __future__ import annotations

from pathlib import Path

from fleetlink.repeater.service import Repeater
from tests.helpers import wait_until
from tests.integration.test_commands_harness import (
    GREEN,
    RED,
    TopicLog,
    distinct,
    fleet,
    lightring_bed,
    repeater_config,
    running_uplink,
    wait_repeater_sees,
)

LEASE_S = 12.0
"""Long enough for the late joiner to join after A's sixth publish (~6 s after it was sent, more
on a loaded machine) and get it while the lease holds."""
TOLERANCE_S = 0.9  # a sample already on its way when the lease ended (under the 1 s period)


def test_late_joiner_lease_end_and_supersede_with_statuses(
    kafka_bootstrap: str, schema_registry_url: str, tmp_path: Path
) -> None:
    with lightring_bed(kafka_bootstrap, schema_registry_url, period="1s", lease=f"{LEASE_S}s") as bed:
        ts, run, commands, producer, leds, site, config = (
            bed.ts,
            bed.run,
            bed.topic,
            bed.producer,
            bed.leds,
            bed.site,
            bed.config,
        )
        with (
            Repeater(repeater_config(site, tmp_path / "state")) as rep,
            fleet(site, ts, leds) as robots,
            TopicLog(kafka_bootstrap, schema_registry_url, config.topics.command_status) as status,
            running_uplink(config) as uplink,
        ):
            router = uplink.commands
            assert router is not None
            robots.add_robot("tb4_01")
            wait_repeater_sees(rep, "/tb4_01/cmd_lightring")

            # A: for tb4_05, which is not there yet; B1 then B2 for tb4_01
            sent_a = producer.send(commands, "tb4_05", RED, command_id=f"A-{run}")
            sent_b1 = producer.send(commands, "tb4_01", RED, command_id=f"B1-{run}")
            wait_until(lambda: leds.first("tb4_01", "red") is not None, timeout=5, message="B1 shown")
            wait_until(lambda: leds.count("tb4_01", "red") >= 2, timeout=5, message="B1 repeated")
            sent_b2 = producer.send(commands, "tb4_01", GREEN, command_id=f"B2-{run}")
            wait_until(lambda: leds.first("tb4_01", "green") is not None, timeout=5, message="B2 shown")
            switched = leds.first("tb4_01", "green")
            assert switched is not None

            # tb4_05 subscribes after A went out five times unheard
            wait_until(
                lambda: rep.stats.by_topic["/tb4_05/cmd_lightring"] >= 1 + 5,
                timeout=10,
                message="A published, then repeated 5 times",
            )
            joined = robots.add_robot("tb4_05")
            assert joined == "tb4_05"
            wait_until(
                lambda: leds.first("tb4_05", "red") is not None, timeout=10, message="late joiner got A"
            )
            got_a = leds.first("tb4_05", "red")
            assert got_a is not None
            assert got_a - sent_a >= 4.0  # it really joined late
            assert got_a < sent_a + LEASE_S  # ... and got it while the lease held
            assert rep.stats.late_joiner_publishes >= 1

            # the leases end: status records for every case
            want = {
                f"A-{run}": ["delivered", "expired"],
                f"B1-{run}": ["delivered", "superseded"],
                f"B2-{run}": ["delivered", "expired"],
            }
            wait_until(
                lambda: all(distinct(status.statuses(cid)) == states for cid, states in want.items()),
                timeout=LEASE_S + 10,
                message=f"statuses {want}",
            )
            records = {(v["command_id"], v["status"]): v for v in status.values()}
            assert records[(f"B1-{run}", "superseded")]["detail"] == f"superseded by B2-{run}"
            assert records[(f"A-{run}", "delivered")]["robot"] == "tb4_05"
            assert all(r["site"] == "site-a" for r in records.values())

            # nothing published after a lease ended, and B1 never again after B2 took over
            before = rep.stats.publishes
            beats = router.intake.heartbeats
            wait_until(
                lambda: router.intake.heartbeats >= beats + 5,
                timeout=10,
                message="the repeater kept talking to the uplink for a while",
            )
            assert rep.stats.publishes == before
            assert all(t <= sent_a + LEASE_S + TOLERANCE_S for t, _ in leds.of("tb4_05"))
            assert all(t <= sent_b2 + LEASE_S + TOLERANCE_S for t, _ in leds.of("tb4_01"))
            assert all(t <= switched for t, name in leds.of("tb4_01") if name == "red")
            assert sent_b1 < sent_b2
            assert router.stats.settled == 3
