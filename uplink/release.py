"""An operator's release of a robot: a tombstone for it on the registrations topic.

Every uplink reads the tombstone and forgets which site held the robot (``RobotDirectory``);
the next site to register it holds it. Compaction removes the robot's last registration too.
"""

from __future__ import annotations

from confluent_kafka import Producer

from fleetlink.common.names import key_path_problem
from fleetlink.uplink.config import UplinkConfig
from fleetlink.uplink.errors import ProduceError, UplinkError


def release_robot(config: UplinkConfig, robot: str, timeout_s: float = 30.0) -> None:
    """Write the tombstone and wait for Kafka's acknowledgement (raises ``UplinkError``)."""
    problem = key_path_problem(robot)
    if problem is not None:
        raise UplinkError(f"robot {robot!r} {problem}")
    producer = Producer(dict(config.kafka.producer_config()))
    errors: list[str] = []
    producer.produce(
        config.topics.registrations,
        key=robot.encode(),
        value=None,
        on_delivery=lambda err, _msg: errors.append(str(err)) if err is not None else None,
    )
    left = producer.flush(timeout_s)
    if left or errors:
        reason = errors[0] if errors else f"no acknowledgement within {timeout_s:.0f} s"
        raise ProduceError(f"releasing {robot}: {reason}", code="_RELEASE", retriable=True)
