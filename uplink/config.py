"""The uplink's one config model (``fleetlink uplink run -c uplink.yaml``)."""

from __future__ import annotations

from pydantic import BaseModel, ConfigDict, Field, field_validator

from fleetlink.common.console_settings import ConsoleSettings
from fleetlink.common.zenoh_options import ZenohSection
from fleetlink.uplink.commands.mapping import CommandMapping, unique_names
from fleetlink.uplink.kafka_settings import KafkaSettings


class RegistrySettings(BaseModel):
    model_config = ConfigDict(extra="forbid")

    url: str = Field(min_length=1, examples=["http://127.0.0.1:8081/apis/ccompat/v7"])
    compatibility: str | None = Field(
        default=None,
        description="set this compatibility level on subjects fleetlink registers (e.g. BACKWARD)",
    )


class TopicSettings(BaseModel):
    model_config = ConfigDict(extra="forbid")

    dead_letter: str = "fleetlink.dead-letter"
    registrations: str = "fleetlink.robots"
    command_dead_letter: str = "fleetlink.commands.dead-letter"
    command_status: str = "fleetlink.commands.status"


class IngestSettings(BaseModel):
    model_config = ConfigDict(extra="forbid")

    sites: list[str] = Field(default=["*"], description="sites served (Zenoh key chunks; * = all)")
    max_concurrent_batches: int = Field(default=64, ge=1, le=10_000)
    batch_deadline_s: float = Field(
        default=60.0, gt=0, description="answer a batch with an error if Kafka has not acked by then"
    )


class MetricsSettings(BaseModel):
    model_config = ConfigDict(extra="forbid")

    listen: str = Field(default="127.0.0.1:9464", description="host:port serving /metrics and /health")


class UplinkConfig(BaseModel):
    model_config = ConfigDict(extra="forbid")

    kafka: KafkaSettings
    registry: RegistrySettings
    zenoh: ZenohSection = ZenohSection()
    topics: TopicSettings = TopicSettings()
    ingest: IngestSettings = IngestSettings()
    commands: list[CommandMapping] = []
    """Command mappings: Kafka topic -> ROS topic per robot (docs/commands.md)."""
    metrics: MetricsSettings | None = None
    """Prometheus ``/metrics`` and ``/health`` over HTTP; off when absent (docs/metrics.md)."""
    console: ConsoleSettings | None = None
    """The fleet web console (every site through the Zenoh admin space); off when absent (docs/console.md)."""

    @field_validator("commands")
    @classmethod
    def _unique_command_names(cls, value: list[CommandMapping]) -> list[CommandMapping]:
        return unique_names(value)
