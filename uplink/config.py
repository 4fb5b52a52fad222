"""The uplink's one config model (``fleetlink uplink run -c uplink.yaml``)."""

from __future__ import annotations

import secrets
import socket
from pathlib import Path

from pydantic import Field, field_validator, model_validator

from fleetlink.common.configfile import Section
from fleetlink.common.console_config import ConsoleSection
from fleetlink.common.durations import Seconds
from fleetlink.common.metrics_config import MetricsSection
from fleetlink.common.names import KafkaTopic, KeyChunk, Site, host_id, site_problem
from fleetlink.common.zenoh_options import ZenohSection
from fleetlink.schemas.typestore import Distro
from fleetlink.uplink.calls.mapping import ActionMapping, ServiceMapping, unique_call_names
from fleetlink.uplink.commands.mapping import CommandMapping, unique_names
from fleetlink.uplink.kafka_settings import KafkaSection
from fleetlink.uplink.policy import pattern_problem


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
    refused: KafkaTopic = "fleetlink.refused"
    """The cloud-side dead-letter topic: records the uplink refused (site, topic and reason in headers)."""
    audit: KafkaTopic = "fleetlink.audit"
    """Who changed what and sent which command from the fleet console (JSON, keyed by user)."""
    marks: KafkaTopic = "fleetlink.marks"
    """The high-water mark of each exactly-once stream, written in its transactions (compacted)."""


class ExactlyOnceSection(Section):
    """How the uplink writes the batches of edges whose spool is ``delivery: exactly_once``."""

    transactional_id_prefix: KeyChunk = "fleetlink"
    """Each exactly-once stream's producer has the transactional id ``<prefix>.<site>.<edge>.<stream>``:
    uplinks of one fleet must share the prefix (it is how one fences another)."""
    transaction_timeout: Seconds = Field(default=60.0, gt=0, le=900)
    """How long Kafka keeps a transaction open before aborting it (``transaction.timeout.ms``)."""
    idle_close: Seconds = Field(default=300.0, gt=0)
    """A stream's producer is closed after this long without a batch (the next one takes it over)."""


class IngestSection(Section):
    sites: list[str] = Field(default=["*"], description="sites served (Zenoh key chunks; * = all)")
    max_concurrent_batches: int = Field(default=64, ge=1, le=10_000)
    native: bool = Field(
        default=True,
        description="produce records through the native path (librdkafka without the GIL, decisions "
        "per tail); false: every record through Python",
    )

    @field_validator("sites")
    @classmethod
    def _sites(cls, value: list[str]) -> list[str]:
        for site in value:
            problem = None if site == "*" else site_problem(site)
            if problem is not None:
                raise ValueError(f"{site!r} {problem} (or '*' for every site)")
        return value


class SitePolicy(Section):
    topics: list[str] = Field(
        default=["*"],
        description="Kafka topic patterns the site may write ('*', '?', '[...]'; {site} is the site's "
        "name); topics fleetlink owns are refused whatever the patterns say",
    )

    @field_validator("topics")
    @classmethod
    def _patterns(cls, value: list[str]) -> list[str]:
        for pattern in value:
            problem = pattern_problem(pattern)
            if problem is not None:
                raise ValueError(f"{pattern!r} {problem}")
        return value


class PolicySection(Section):
    """Where each site may write (docs/security.md): ``default`` for every site, ``sites`` per site."""

    default: SitePolicy = SitePolicy()
    sites: dict[Site, SitePolicy] = {}

    def patterns(self) -> dict[str, list[str]]:
        return {site: policy.topics for site, policy in self.sites.items()}


class OwnershipSection(Section):
    release_after: Seconds = Field(
        default=0.0,
        ge=0,
        description="how long a robot deregistered by its site (liveliness lost for the edge's grace "
        "period) stays that site's before another site may register it",
    )


class CommandSigningSection(Section):
    key_file: Path = Field(
        description="the Ed25519 private key (PEM) command envelopes are signed with "
        "(fleetlink certs command-key); repeaters hold its public key"
    )


class UplinkRosSection(Section):
    distro: Distro = "jazzy"
    """The robots' ROS distro: decides the request, response, goal, feedback and result types."""
    message_paths: list[Path] = []
    """Folders of interface packages the service and action mappings use beyond the bundled ones."""


__all__ = ["MetricsSection", "UplinkConfig"]


def default_uplink_id() -> str:
    """The host name and a few random characters: uplinks may share a host, and a restarted
    uplink's counters start again under a new name (consoles then measure them afresh)."""
    return f"{host_id(socket.gethostname(), 'uplink')[:55]}-{secrets.token_hex(3)}"


class UplinkConfig(Section):
    """Everything one uplink process needs: Kafka and the schema registry, the sites it serves, and the
    command, service and action mappings."""

    id: KeyChunk = Field(default_factory=default_uplink_id)
    """Names this uplink in the delivery figures consoles add up (``fleetlink/<site>/delivery/<id>``)."""
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
    policy: PolicySection = PolicySection()
    """The Kafka topics each site may write (docs/security.md)."""
    ownership: OwnershipSection = OwnershipSection()
    """When a robot may move to another site (docs/security.md)."""
    exactly_once: ExactlyOnceSection = ExactlyOnceSection()
    """Transactions for the edges that ask for exactly-once delivery (docs/exactly-once.md)."""
    command_signing: CommandSigningSection | None = None
    """The key commands and calls are signed with; required with command, service and action mappings."""
    services: list[ServiceMapping] = []
    """Service mappings: Kafka requests -> ROS service calls, replies to Kafka (docs/services.md)."""
    actions: list[ActionMapping] = []
    """Action mappings: Kafka goals -> ROS action goals, feedback and results to Kafka (docs/services.md)."""
    ros: UplinkRosSection = UplinkRosSection()
    """The ROS types of the service and action mappings (docs/services.md)."""

    @field_validator("commands")
    @classmethod
    def _unique_command_names(cls, value: list[CommandMapping]) -> list[CommandMapping]:
        return unique_names(value)

    @model_validator(mode="after")
    def _signing_key_for_commands(self) -> UplinkConfig:
        if (self.commands or self.services or self.actions) and self.command_signing is None:
            raise ValueError(
                "command_signing.key_file is required with command, service and action mappings: "
                "repeaters accept only signed commands and calls "
                "(make a key with 'fleetlink certs command-key DIR')"
            )
        unique_call_names(self.services, self.actions)
        return self
