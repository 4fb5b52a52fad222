"""Commands from Kafka reach exactly the addressed robot, at its site, within a bounded latency.

Two sites behind their own WAN relays, each with a repeater and simulated robots; robots are
registered through the registrations topic (tb4_01, tb4_02 at site-a; tb4_03 at site-b).
"""

from __future__ import annotations

from pathlib import Path

from fleetlink.repeater.service import Repeater
from fleetlink.uplink.commands.mapping import CommandMapping
from tests.helpers import wait_until
from tests.integration.test_commands_harness import (
    BLUE,
    GREEN,
    RED,
    CommandProducer,
    LedLog,
    TopicLog,
    Wan,
    create_topics,
    fleet,
    irobot_store,
    lightring_mapping,
    repeater_config,
    running_uplink,
    uid,
    uplink_config,
    wait_repeater_sees,
)


def test_command_reaches_only_the_addressed_robot_and_unknown_robots_reach_every_site(
    kafka_bootstrap: str, schema_registry_url: str, tmp_path: Path
) -> None:
    ts = irobot_store()
    run = uid()
    commands = f"cmd.lightring.{run}"
    producer = CommandProducer(kafka_bootstrap, schema_registry_url, ts)
    leds = LedLog()
    with Wan() as wan:
        a, b = wan.add_site("site-a"), wan.add_site("site-b")
        config = uplink_config(
            kafka_bootstrap,
            schema_registry_url,
            wan.cloud.endpoint,
            [lightring_mapping(commands)],
            suffix=run,
        )
        create_topics(kafka_bootstrap, commands, config.topics.registrations)
        for robot, site in (("tb4_01", "site-a"), ("tb4_02", "site-a"), ("tb4_03", "site-b")):
            producer.register(config.topics.registrations, robot, site)
        with (
            Repeater(repeater_config(a, tmp_path / "a")) as rep_a,
            Repeater(repeater_config(b, tmp_path / "b")) as rep_b,
            fleet(a, ts, leds) as robots_a,
            fleet(b, ts, leds) as robots_b,
            TopicLog(kafka_bootstrap, schema_registry_url, config.topics.command_status) as status,
        ):
            robots_a.add_robot("tb4_01")
            robots_a.add_robot("tb4_02")
            robots_b.add_robot("tb4_03")
            for rep, robot in ((rep_a, "tb4_01"), (rep_a, "tb4_02"), (rep_b, "tb4_03")):
                wait_repeater_sees(rep, f"/{robot}/cmd_lightring")
            with running_uplink(config) as uplink:
                router = uplink.commands
                assert router is not None
                wait_until(
                    lambda: router.directory.site_of("tb4_03") == "site-b",
                    timeout=10,
                    message="registrations read",
                )

                sent = producer.send(commands, "tb4_02", RED, command_id=f"red-{run}")
                wait_until(
                    lambda: leds.first("tb4_02", "red") is not None, timeout=5, message="tb4_02 shows red"
                )
                first = leds.first("tb4_02", "red")
                assert first is not None
                assert first - sent < 5.0
                # repeats keep coming at the period; meanwhile nobody else saw anything
                wait_until(lambda: leds.count("tb4_02", "red") >= 3, timeout=5, message="two repeats")
                assert leds.count("tb4_01") == 0
                assert leds.count("tb4_03") == 0
                assert (rep_a.stats.applied, rep_b.stats.applied) == (1, 0)
                wait_until(
                    lambda: "delivered" in status.statuses(f"red-{run}", "tb4_02"),
                    timeout=10,
                    message="delivered status",
                )
                delivered = next(v for v in status.values() if v["command_id"] == f"red-{run}")
                assert (delivered["site"], delivered["ros_topic"]) == ("site-a", "/tb4_02/cmd_lightring")

                # a robot nobody registered: every site's repeater takes the command
                producer.send(commands, "tb4_09", GREEN, command_id=f"green-{run}")
                wait_until(
                    lambda: rep_a.stats.applied == 2 and rep_b.stats.applied == 1,
                    timeout=10,
                    message="both sites applied the command for the unknown robot",
                )
                robots_b.add_robot("tb4_09")  # it turns up at site-b: late joiner, still leased
                wait_until(
                    lambda: leds.first("tb4_09", "green") is not None, timeout=5, message="tb4_09 shows green"
                )
                wait_until(
                    lambda: any(
                        v["command_id"] == f"green-{run}"
                        and v["status"] == "delivered"
                        and v["site"] == "site-b"
                        for v in status.values()
                    ),
                    timeout=10,
                    message="delivered at site-b",
                )
                assert leds.count("tb4_01") == 0
                assert not any(
                    v["command_id"] == f"green-{run}" and v["status"] == "delivered" and v["site"] == "site-a"
                    for v in status.values()
                )
                assert router.stats.dead_lettered == 0

                # mappings change at runtime: a second Kafka topic, routed without a restart
                second = f"cmd.lightring2.{run}"
                create_topics(kafka_bootstrap, second)
                extra = CommandMapping.model_validate(lightring_mapping(second, name="lightring2"))
                router.set_mappings([*config.commands, extra])
                producer.send(second, "tb4_01", BLUE, command_id=f"blue-{run}")
                wait_until(
                    lambda: leds.first("tb4_01", "blue") is not None,
                    timeout=20,
                    message="a command from the new mapping",
                )
