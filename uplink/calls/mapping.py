"""Service and action mappings: a Kafka topic of requests (or goals) -> a ROS service (or action)
of each addressed robot, and Kafka topics for what comes back.

::

    ros: {distro: jazzy}                       # the types (bundled packages + message_paths)
    services:
      - name: estop                            # one key chunk: fleetlink/<site>/call/<robot>/estop
        from: fleet.services.estop             # requests: Avro of irobot_create_msgs/srv/EStop_Request
        to: "/{robot}/e_stop"                  # the ROS service of each robot
        type: irobot_create_msgs/srv/EStop
        reply_to: fleet.services.estop.replies # responses, timeouts and errors, keyed by robot
        timeout: 5s
    actions:
      - name: dock
        from: fleet.actions.dock               # goals: Avro of irobot_create_msgs/action/Dock_Goal
        to: "/{robot}/dock"
        type: irobot_create_msgs/action/Dock
        cancel_from: fleet.actions.dock.cancel # optional: {goal_id, robot} records cancel a goal
        feedback_to: fleet.actions.dock.feedback
        result_to: fleet.actions.dock.results  # accepted, then the final status and result
        timeout: 60s

``to`` may use ``{robot}`` only; **which robot** a request or goal addresses is ``robot:``
(``"{key}"``, the default, or ``"{msg.<field>}"``); a cancel record names its robot itself.
"""

from __future__ import annotations

from pydantic import ConfigDict, Field, field_validator, model_validator

from fleetlink.common.configfile import Section
from fleetlink.common.durations import PositiveSeconds
from fleetlink.common.names import KafkaTopic, KeyChunk, RosActionType, RosServiceType
from fleetlink.uplink.commands.mapping import (
    Ref,
    Template,
    check_robot_template,
    check_ros_template,
    parse_template,
)


class CallMapping(Section):
    """What services and actions share."""

    model_config = ConfigDict(populate_by_name=True, frozen=True)

    name: KeyChunk
    from_: KafkaTopic = Field(alias="from")
    to: str
    robot: str = "{key}"
    timeout: PositiveSeconds = 5.0
    """How long a call may take from its Kafka record's timestamp."""

    @field_validator("to")
    @classmethod
    def _to(cls, value: str) -> str:
        return check_ros_template(value, "ROS name", robot_only=True)

    @field_validator("robot")
    @classmethod
    def _robot(cls, value: str) -> str:
        return check_robot_template(value)

    @property
    def to_template(self) -> Template:
        """``to`` parsed into literals and the ``{robot}`` placeholder."""
        return parse_template(self.to)

    @property
    def robot_ref(self) -> Ref:
        """Where the addressed robot comes from: the record key or a field of the record."""
        return parse_template(self.robot).refs[0]

    @property
    def timeout_ms(self) -> int:
        """``timeout`` in whole milliseconds (at least 1)."""
        return max(1, round(self.timeout * 1000))


class ServiceMapping(CallMapping):
    """Kafka requests -> one ROS service per addressed robot; replies to ``reply_to``."""

    type: RosServiceType
    reply_to: KafkaTopic


class ActionMapping(CallMapping):
    """Kafka goals -> one ROS action per addressed robot; feedback and results to Kafka."""

    type: RosActionType
    cancel_from: KafkaTopic | None = None
    feedback_to: KafkaTopic
    result_to: KafkaTopic
    timeout: PositiveSeconds = 60.0
    """How long a goal may run from its Kafka record's timestamp (then it is canceled: ``timeout``)."""

    @model_validator(mode="after")
    def _topics(self) -> ActionMapping:
        if self.cancel_from is not None and self.cancel_from == self.from_:
            raise ValueError(
                "cancel_from must differ from 'from' (goals and cancels are told apart by topic)"
            )
        return self


def unique_call_names(services: list[ServiceMapping], actions: list[ActionMapping]) -> None:
    """Raise ``ValueError`` when two call mappings share a name (it is part of the call's key)."""
    seen: set[str] = set()
    for mapping in [*services, *actions]:
        if mapping.name in seen:
            raise ValueError(f"two service/action mappings are named {mapping.name!r}")
        seen.add(mapping.name)
