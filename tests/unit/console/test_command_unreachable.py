"""A console command while Kafka cannot be reached: refused as not sent, and never sent later."""

from __future__ import annotations

import pytest

from fleetlink.console.kafka_ops import KafkaCommands
from fleetlink.console.operations import CommandRefusedError
from fleetlink.localstack.process import free_port

SCHEMA = {"type": "record", "name": "Led", "fields": [{"name": "on", "type": "boolean"}]}


def test_a_command_kafka_never_took_is_refused_as_not_sent() -> None:
    commands = KafkaCommands(
        {"bootstrap.servers": f"127.0.0.1:{free_port()}", "log_level": 0},  # nothing listens there
        [{"name": "led", "from": "fleet.led", "to": "/led", "type": "std_msgs/msg/Bool"}],
        schema_for=lambda _topic, _type: SCHEMA,
        register=lambda _subject, _schema: 1,
        statuses=[],
        robots=lambda: ["tb4_01"],
        timeout_s=0.5,
    )
    with pytest.raises(CommandRefusedError, match=r"not reached within 0\.5 s: command not sent"):
        commands.send("led", "tb4_01", {"on": True}, user="ops")
    # taken back from the producer's queue: nothing is left to be sent once Kafka is back
    assert len(commands._producer) == 0
    commands.close()
