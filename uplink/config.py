"""The uplink's one config model (``fleetlink uplink run -c uplink.yaml``)."""

from __future__ import annotations

from pydantic import Field, field_validator

from fleetlink.common.configfile import Section
from fleetlink.common.console_config import ConsoleSection
from fleetlink.common.names import KafkaTopic, site_problem
from fleetlink.common.zenoh_options import ZenohSection
from fleetlink.uplink.commands.mapping import CommandMapping, unique_names
from fleetlink.uplink.kafka_settings import KafkaSection


class RegistrySection(Section):
    url: str = Field(min_length=1, examples=["http://127.0.0.1:8081/apis/ccompat/v7"])
    compatibility: str | None = Field(
        default=None,
        description="set this compatibility level on subjects fleetlink registers (e.g. BACKWARD)",
    )


class TopicsSection(Section):
    dead_letter: KafkaTopic = "fleetlink.dead-letter"
    registrations: KafkaTopic = "fleetlink.robots"
    command_dead_letter: KafkaTopic = "fleetlink.commands.dead-letter"
    command_status: KafkaTopic = "fleetlink.commands.status"


class IngestSection(Section):
    sites: list[str] = Field(default=["*"], description="sites served (Zenoh key chunks; * = all)")
    max_concurrent_batches: int = Field(default=64, ge=1, le=10_000)

    @field_validator("sites")
    @classmethod
    def _sites(cls, value: list[str]) -> list[str]:
        for site in value:
            problem = None if site == "*" else site_problem(site)
            if problem is not None:
                raise ValueError(f"{site!r} {problem} (or '*' for every site)")
        return value


class MetricsSection(Section):
    listen: str = Field(default="127.0.0.1:9464", description="host:port serving /metrics and /health")


class UplinkConfig(Section):
    kafka: KafkaSection
    registry: RegistrySection
    zenoh: ZenohSection = ZenohSection()
    topics: TopicsSection = TopicsSection()
    ingest: IngestSection = IngestSection()
    commands: list[CommandMapping] = []
    """Command mappings: Kafka topic -> ROS topic per robot (docs/commands.md)."""
    metrics: MetricsSection | None = None
    """Prometheus ``/metrics`` and ``/health`` over HTTP; off when absent (docs/metrics.md)."""
    console: ConsoleSection | None = None
    """The fleet web console (every site through the Zenoh admin space); off when absent (docs/console.md)."""

    @field_validator("commands")
    @classmethod
    def _unique_command_names(cls, value: list[CommandMapping]) -> list[CommandMapping]:
        return unique_names(value)
