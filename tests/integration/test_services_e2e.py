"""Service calls and action goals from Kafka to simulated robots and back, through real parts:
Kafka and the registry, a cloud router and a site router linked by a WAN relay, the uplink, the
repeater and TurtleBot 4 robots serving rmw_zenoh services and actions (docs/services.md).

Also the failure rows of docs/guarantees.md: a service that never answers (timeout), a robot
whose process is killed during a goal (robot gone), a cancel of a finished goal, a robot no
site holds, and the same goal delivered twice.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
import uuid
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from confluent_kafka import Producer
from confluent_kafka.schema_registry import SchemaRegistryClient
from confluent_kafka.schema_registry.avro import AvroSerializer
from confluent_kafka.serialization import MessageField, SerializationContext

from fleetlink.repeater.service import Repeater
from fleetlink.roswire.node import RosNode
from fleetlink.roswire.service import RosServiceServer, ServiceCall
from fleetlink.schemas.avro_schema import avro_schema
from fleetlink.uplink.calls.records import CANCEL_SCHEMA
from fleetlink.uplink.config import UplinkConfig
from fleetlink.uplink.service import Uplink
from tests.helpers import wait_until
from tests.integration.test_commands_harness import (
    LedLog,
    Site,
    TopicLog,
    Wan,
    create_topics,
    fleet,
    irobot_store,
    repeater_config,
    robot_config,
    running_uplink,
    uid,
    uplink_config,
)

ESTOP = "irobot_create_msgs/srv/EStop"
TRIGGER = "std_srvs/srv/Trigger"
DOCK = "irobot_create_msgs/action/Dock"


class Requests:
    """Produces request, goal and cancel records as an application does: stock AvroSerializer
    with the schema fleetlink derives from the ROS type, key = robot (cancels: goal id)."""

    def __init__(self, bootstrap: str, registry_url: str) -> None:
        self.ts = irobot_store()
        self.client = SchemaRegistryClient({"url": registry_url})
        self.producer = Producer({"bootstrap.servers": bootstrap, "linger.ms": 0})

    def send(
        self,
        topic: str,
        key: str,
        schema: dict[str, Any],
        datum: dict[str, Any],
        headers: list[tuple[str, bytes]] | None = None,
    ) -> None:
        serializer = AvroSerializer(self.client, json.dumps(schema), to_dict=lambda obj, _ctx: obj)
        value = serializer(datum, SerializationContext(topic, MessageField.VALUE))
        errors: list[Any] = []
        self.producer.produce(
            topic,
            key=key.encode(),
            value=value,
            headers=headers or [],
            on_delivery=lambda e, _m: errors.append(e),
        )
        self.producer.flush(10)
        assert errors == [None], errors

    def request(self, topic: str, robot: str, typename: str, datum: dict[str, Any], call_id: str) -> None:
        schema = avro_schema(self.ts, f"{typename}_Request", "jazzy")
        self.send(topic, robot, schema, datum, [("fleetlink-correlation-id", call_id.encode())])

    def goal(self, topic: str, robot: str, goal_id: str) -> None:
        schema = avro_schema(self.ts, f"{DOCK}_Goal", "jazzy")
        self.send(
            topic,
            robot,
            schema,
            {"structure_needs_at_least_one_member": 0},
            [("fleetlink-goal-id", goal_id.encode())],
        )

    def cancel(self, topic: str, robot: str, goal_id: str) -> None:
        self.send(topic, goal_id, CANCEL_SCHEMA, {"goal_id": goal_id, "robot": robot})


@dataclass
class Bed:
    run: str
    site: Site
    config: UplinkConfig
    topics: dict[str, str]
    requests: Requests


@contextmanager
def call_bed(bootstrap: str, registry_url: str) -> Iterator[Bed]:
    run = uid()
    t = {
        name: f"{name}.{run}"
        for name in (
            "estop",
            "estop.replies",
            "slow",
            "slow.replies",
            "dock",
            "dock.cancel",
            "dock.feedback",
            "dock.results",
        )
    }
    with Wan() as wan:
        site = wan.add_site("site-a")
        base = uplink_config(bootstrap, registry_url, wan.cloud.endpoint, [], suffix=run)
        data = base.model_dump(mode="json", by_alias=True)
        data["services"] = [
            {
                "name": "estop",
                "from": t["estop"],
                "to": "/{robot}/e_stop",
                "type": ESTOP,
                "reply_to": t["estop.replies"],
            },
            {
                "name": "slow",
                "from": t["slow"],
                "to": "/{robot}/take_a_while",
                "type": TRIGGER,
                "reply_to": t["slow.replies"],
                "timeout": "1500ms",
            },
        ]
        data["actions"] = [
            {
                "name": "dock",
                "from": t["dock"],
                "to": "/{robot}/dock",
                "type": DOCK,
                "cancel_from": t["dock.cancel"],
                "feedback_to": t["dock.feedback"],
                "result_to": t["dock.results"],
                "timeout": "20s",
            }
        ]
        config = UplinkConfig.model_validate(data)
        create_topics(bootstrap, *t.values(), config.topics.registrations)
        yield Bed(run, site, config, t, Requests(bootstrap, registry_url))


def _register(bed: Bed, robot: str) -> None:
    from tests.integration.test_commands_harness import CommandProducer

    producer = CommandProducer(bed.config.kafka.bootstrap_servers, bed.config.registry.url, bed.requests.ts)
    producer.register(bed.config.topics.registrations, robot, bed.site.name)


def _wait_registered(uplink: Uplink, robot: str) -> None:
    """Wait until the uplink's command router knows ``robot`` is at site-a."""
    wait_until(
        lambda: uplink.commands is not None and uplink.commands.directory.site_of(robot) == "site-a",
        timeout=10,
        message="registered",
    )


def _one(log: TopicLog, predicate: Any, message: str, timeout: float = 15.0) -> dict[str, Any]:
    wait_until(lambda: any(predicate(v) for v in log.values()), timeout=timeout, message=message)
    return next(v for v in log.values() if predicate(v))


def test_services_and_actions_from_kafka_reach_the_robot_and_come_back(
    kafka_bootstrap: str, schema_registry_url: str, tmp_path: Path
) -> None:
    with call_bed(kafka_bootstrap, schema_registry_url) as bed:
        t, req = bed.topics, bed.requests
        _register(bed, "tb4_01")
        with (
            Repeater(repeater_config(bed.site, tmp_path / "rep")) as repeater,
            fleet(bed.site, req.ts, LedLog()) as robots,
            TopicLog(kafka_bootstrap, schema_registry_url, t["estop.replies"]) as replies,
            TopicLog(kafka_bootstrap, schema_registry_url, t["dock.results"]) as results,
            TopicLog(kafka_bootstrap, schema_registry_url, t["dock.feedback"]) as feedback,
        ):
            robots.add_robot("tb4_01")
            with running_uplink(bed.config) as uplink:
                router = uplink.commands
                assert router is not None
                _wait_registered(uplink, "tb4_01")

                # a service call: the robot's e-stop goes on, the response comes back keyed by robot
                req.request(t["estop"], "tb4_01", ESTOP, {"e_stop_on": True}, f"stop-{bed.run}")
                reply = _one(replies, lambda v: v["correlation_id"] == f"stop-{bed.run}", "e-stop reply")
                assert (reply["status"], reply["robot"], reply["service"], reply["site"]) == (
                    "ok",
                    "tb4_01",
                    "/tb4_01/e_stop",
                    "site-a",
                )
                assert reply["response"]["success"] is True
                assert reply["response"]["message"] == "e-stop on"
                assert robots.model("tb4_01").e_stop is True
                record = next(r for r in replies.records if r["value"]["correlation_id"] == f"stop-{bed.run}")
                assert record["key"] == b"tb4_01"
                assert record["headers"]["fleetlink-correlation-id"] == f"stop-{bed.run}".encode()

                # a robot no site holds: answered at once by the uplink, nothing sent
                req.request(t["estop"], "tb4_77", ESTOP, {"e_stop_on": True}, f"ghost-{bed.run}")
                ghost = _one(replies, lambda v: v["correlation_id"] == f"ghost-{bed.run}", "ghost reply")
                assert ghost["status"] == "unavailable"
                assert ghost["response"] is None

                # an action goal: accepted, feedback, then succeeded with the result; the robot docks
                goal = str(uuid.uuid4())
                req.goal(t["dock"], "tb4_01", goal)
                done = _one(
                    results, lambda v: v["goal_id"] == goal and v["status"] == "succeeded", "dock result"
                )
                assert done["result"] == {"is_docked": True}
                statuses = [v["status"] for v in results.values() if v["goal_id"] == goal]
                assert statuses == ["accepted", "succeeded"]
                assert robots.model("tb4_01").docked is True
                fbs = [v for v in feedback.values() if v["goal_id"] == goal]
                assert len(fbs) >= 5  # 2 s at 10 Hz, some may still be on the way
                assert {"sees_dock": False} in [f["feedback"] for f in fbs]
                assert all(
                    r["key"] == goal.encode() for r in results.records if r["value"]["goal_id"] == goal
                )

                # the same goal again (a re-delivery): the site runs it once
                received = robots.services("tb4_01")
                req.goal(t["dock"], "tb4_01", goal)
                wait_until(
                    lambda: repeater.call_intake is not None and repeater.call_intake.duplicates == 1,
                    timeout=10,
                    message="duplicate seen",
                )
                dock_server = (
                    next(s for s in received._servers if getattr(s, "action", "") == "/tb4_01/dock")
                    if received
                    else None
                )
                assert dock_server is not None
                assert dock_server.goals_received == 1  # type: ignore[union-attr]

                # cancel of a finished goal: the robot says it had finished
                req.cancel(t["dock.cancel"], "tb4_01", goal)
                cancel = _one(
                    results, lambda v: v["goal_id"] == goal and v["status"].startswith("cancel-"), "cancel"
                )
                assert cancel["status"] == "cancel-terminated"
                assert "already finished" in cancel["detail"]
                assert router.stats.dead_lettered == 0


def test_a_service_that_never_answers_times_out(
    kafka_bootstrap: str, schema_registry_url: str, tmp_path: Path
) -> None:
    with call_bed(kafka_bootstrap, schema_registry_url) as bed:
        t, req = bed.topics, bed.requests
        _register(bed, "tb4_01")
        held: list[ServiceCall] = []
        with (
            Repeater(repeater_config(bed.site, tmp_path / "rep")),
            RosNode("slow", "/tb4_01", config=robot_config(bed.site.endpoint), typestore=req.ts) as node,
            TopicLog(kafka_bootstrap, schema_registry_url, t["slow.replies"]) as replies,
        ):

            def hold(call: ServiceCall) -> None:  # never answers
                held.append(call)

            RosServiceServer(node, "take_a_while", TRIGGER, hold).start()
            with running_uplink(bed.config) as uplink:
                assert uplink.commands is not None
                _wait_registered(uplink, "tb4_01")
                req.request(
                    t["slow"],
                    "tb4_01",
                    TRIGGER,
                    {"structure_needs_at_least_one_member": 0},
                    f"slow-{bed.run}",
                )
                reply = _one(replies, lambda v: v["correlation_id"] == f"slow-{bed.run}", "slow reply")
                assert reply["status"] == "timeout"
                assert reply["response"] is None
                assert len(held) == 1  # the request reached the robot, once
                elapsed = reply["at"] - reply["requested_at"]
                assert 1500 <= _millis(elapsed) < 4000


def _millis(value: Any) -> float:
    return value.total_seconds() * 1000 if hasattr(value, "total_seconds") else float(value)


def test_a_robot_killed_during_a_goal_is_reported_not_retried(
    kafka_bootstrap: str, schema_registry_url: str, tmp_path: Path
) -> None:
    with call_bed(kafka_bootstrap, schema_registry_url) as bed:
        t, req = bed.topics, bed.requests
        _register(bed, "tb4_01")
        env = {**os.environ, "PYTHONUNBUFFERED": "1"}
        sim = subprocess.Popen(
            [
                sys.executable,
                "-m",
                "fleetlink",
                "ros",
                "sim",
                "--robots",
                "1",
                "--rate",
                "1",
                "-m",
                "client",
                "-e",
                bed.site.endpoint,
            ],
            env=env,
            stdout=(tmp_path / "sim.log").open("w"),
            stderr=subprocess.STDOUT,
        )
        try:
            with (
                Repeater(repeater_config(bed.site, tmp_path / "rep")) as repeater,
                TopicLog(kafka_bootstrap, schema_registry_url, t["dock.results"]) as results,
                running_uplink(bed.config) as uplink,
            ):
                assert uplink.commands is not None
                _wait_registered(uplink, "tb4_01")
                goal = str(uuid.uuid4())
                req.goal(t["dock"], "tb4_01", goal)
                _one(
                    results,
                    lambda v: v["goal_id"] == goal and v["status"] == "accepted",
                    "accepted",
                    timeout=30,
                )
                sim.send_signal(signal.SIGKILL)  # the robot's process dies mid-goal (docking takes 2 s)
                sim.wait(10)
                final = _one(results, lambda v: v["goal_id"] == goal and v["status"] != "accepted", "final")
                assert final["status"] == "error"
                assert "went away" in final["detail"]
                assert final["result"] is None
                time.sleep(1.0)  # ok-sleep: a window in which no second outcome may come
                # outcomes are at least once (a batch whose answer came late is sent again, the
                # same outcome with the same time): a retried goal would make a new one
                outcomes = dict.fromkeys(
                    (v["status"], v["at"]) for v in results.values() if v["goal_id"] == goal
                )
                assert [status for status, _at in outcomes] == ["accepted", "error"]
                assert repeater.calls.calls[("goal", goal, "tb4_01")].done
        finally:
            if sim.poll() is None:
                sim.kill()
                sim.wait(10)


def test_an_operator_docks_a_robot_and_calls_its_e_stop_from_the_console(
    kafka_bootstrap: str, schema_registry_url: str, tmp_path: Path
) -> None:
    """The fleet console lists the service and action mappings beside the command ones; an
    operator sends a Dock goal and an e-stop request to a robot (a record on each mapping's Kafka
    topic, as an app writes one) and follows their outcomes from the results and replies topics."""
    import httpx

    from fleetlink.common.console_config import ConsoleSection
    from fleetlink.console.uplink import UplinkConsole, console_extensions
    from fleetlink.console.users import hash_password

    users = tmp_path / "users.yaml"
    users.write_text(
        f"users:\n  - {{name: lin, role: operator, password_hash: '{hash_password('operator-pass-1')}'}}\n"
    )
    with call_bed(kafka_bootstrap, schema_registry_url) as bed:
        _register(bed, "tb4_01")
        console = ConsoleSection(listen="127.0.0.1:0", token_env=None, users_file=users, poll_interval=0.5)
        config = bed.config.model_copy(update={"console": console})
        with (
            Repeater(repeater_config(bed.site, tmp_path / "rep")),
            fleet(bed.site, bed.requests.ts, LedLog()) as robots,
        ):
            robots.add_robot("tb4_01")
            with Uplink(config, extensions=console_extensions(config)) as uplink:
                _wait_registered(uplink, "tb4_01")
                [extension] = uplink.extensions
                assert isinstance(extension, UplinkConsole)
                base = f"{extension.url}/console/"
                change = {"X-Fleetlink-Console": "1"}
                with httpx.Client(base_url=base, auth=("lin", "operator-pass-1"), timeout=20) as operator:
                    listed = operator.get("api/command-mappings").json()["mappings"]
                    assert {(m["name"], m["kind"]) for m in listed} == {
                        ("estop", "service"),
                        ("slow", "service"),
                        ("dock", "action"),
                    }
                    goal = operator.post(
                        "api/commands/send",
                        json={"mapping": "dock", "robot": "tb4_01", "value": "{}"},
                        headers=change,
                    )
                    assert goal.status_code == 201, goal.text
                    stop = operator.post(
                        "api/commands/send",
                        json={"mapping": "estop", "robot": "tb4_01", "value": "e_stop_on: true"},
                        headers=change,
                    )
                    assert stop.status_code == 201, stop.text
                    ids = [goal.json()["result"]["command_id"], stop.json()["result"]["command_id"]]
                    uuid.UUID(ids[0])  # a goal id is a UUID, as the action protocol's

                    def outcomes() -> dict[str, list[str]]:
                        found = operator.get(f"api/commands/status?ids={','.join(ids)}").json()["statuses"]
                        return {k: [s["status"] for s in v] for k, v in found.items()}

                    wait_until(
                        lambda: outcomes()[ids[0]][-1:] == ["succeeded"] and outcomes()[ids[1]] == ["ok"],
                        timeout=30,
                        message=f"dock succeeded and e-stop answered: {outcomes()}",
                    )
                    assert outcomes()[ids[0]] == ["accepted", "succeeded"]
                assert robots.model("tb4_01").docked is True
                assert robots.model("tb4_01").e_stop is True
        # every call is in the audit topic: who sent what, with its id
        with TopicLog(kafka_bootstrap, schema_registry_url, config.topics.audit, avro=False) as audit:

            def audited() -> list[dict[str, Any]]:
                found = (json.loads(r["value"]) for r in list(audit.records))
                return [r for r in found if (r.get("detail") or {}).get("command_id") in ids]

            wait_until(lambda: len(audited()) == 2, timeout=20, message="the calls in the audit topic")
            sent = audited()
        assert {(r["user"], r["role"], r["action"], r["target"], r["status"]) for r in sent} == {
            ("lin", "operator", "command.send", "tb4_01", 201)
        }
        assert {r["detail"]["mapping"] for r in sent} == {"dock", "estop"}
