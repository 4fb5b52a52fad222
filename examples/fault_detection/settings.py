"""The app's settings: one typed, frozen model; durations parsed from ``2s`` / ``500ms`` / ``1m``.

Pure: nothing here reads the environment, the disk or the network.
"""

from __future__ import annotations

import re
from collections.abc import Mapping
from pathlib import Path
from typing import Literal

from pydantic import ConfigDict, Field, PositiveInt

from fleetlink.common import durations
from fleetlink.common.configfile import Section
from fleetlink.common.durations import PositiveSeconds, Seconds
from fleetlink.common.names import KafkaTopic
from fleetlink.examples.fault_detection.errors import SettingsError
from fleetlink.examples.fault_detection.rules import HAZARD_CLIFF, HAZARD_WHEEL_DROP, RuleConfig

__all__ = [
    "DEFAULT_STATE_DIR",
    "FaultDetectionSettings",
    "Topics",
    "check_copartitioned",
    "parse_duration_ms",
]

DEFAULT_STATE_DIR = Path.home() / ".cache" / "fleetlink" / "fault-detection"

_BARE_NUMBER = re.compile(r"^\s*\d+(?:\.\d+)?\s*$")


def parse_duration_ms(text: str) -> int:
    """``"2s"`` → 2000, ``"500ms"`` → 500, ``"1.5s"`` → 1500, ``"1m"`` → 60000; a bare number is seconds.

    The result must be a positive whole number of milliseconds.
    """
    value: object = text
    if _BARE_NUMBER.match(text):
        value = float(text)  # the shared parser reads numbers, not numeric text, as seconds
    try:
        return durations.parse_duration_ms(value)
    except ValueError as exc:
        raise SettingsError(f"invalid duration {text!r}: {exc}; e.g. 2s, 500ms, 1.5s or 1m") from None


class Topics(Section):
    """Kafka topics the app reads (one per sensor) and writes (light-ring commands)."""

    model_config = ConfigDict(frozen=True)

    ir_intensity: KafkaTopic = "fleet.ir_intensity"
    hazard_detection: KafkaTopic = "fleet.hazard_detection"
    kidnap_status: KafkaTopic = "fleet.kidnap_status"
    commands: KafkaTopic = "fleet.commands.lightring"


class FaultDetectionSettings(Section):
    """Everything the app needs.

    ``msg_paths``: ROS package folders to take the irobot_create_msgs definitions from; empty
    means the copy fleetlink ships (``schemas/msgs``).
    """

    model_config = ConfigDict(frozen=True)

    bootstrap: str = Field(min_length=1, description="Kafka bootstrap servers, HOST:PORT[,...]")
    registry_url: str = Field(min_length=1, description="Confluent-compatible schema registry URL")
    window: PositiveSeconds = 2.0
    """The sliding window per robot (``2s``)."""
    grace: Seconds = Field(default=1.0, ge=0)
    """How late a record may arrive and still count."""
    group: str = Field(default="fleetlink-fault-detection", min_length=1)
    state_dir: Path = DEFAULT_STATE_DIR
    offset_reset: Literal["earliest", "latest"] = "latest"
    ir_threshold: int = 3000
    failure_hazards: frozenset[int] = frozenset({HAZARD_WHEEL_DROP, HAZARD_CLIFF})
    min_events: PositiveInt = 2
    distro: Literal["humble", "jazzy", "kilted"] = "jazzy"
    msg_paths: tuple[Path, ...] = ()
    topics: Topics = Topics()
    poll_timeout: PositiveSeconds = 0.2
    commit_interval: PositiveSeconds = 1.0

    def rule_config(self) -> RuleConfig:
        """The rule parameters of these settings (IR threshold, failure hazards, minimum events)."""
        return RuleConfig(
            ir_threshold=self.ir_threshold,
            failure_hazards=self.failure_hazards,
            min_events=self.min_events,
        )


def check_copartitioned(partitions: Mapping[str, int]) -> None:
    """The sensor topics that exist must have one partition count between them.

    A robot's windows and state live in the partition its key hashes to; with different
    partition counts its IR, hazard and kidnap records would land in different partitions
    and never meet in one window. ``partitions`` maps each existing topic to its count.
    """
    counts = set(partitions.values())
    if len(counts) > 1:
        listing = ", ".join(f"{name}={count}" for name, count in sorted(partitions.items()))
        raise SettingsError(
            f"the sensor topics must have the same number of partitions (a robot's records must meet "
            f"in one partition), got {listing}"
        )
