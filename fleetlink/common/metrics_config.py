"""The ``metrics:`` section of the uplink's and the repeater's configs."""

from __future__ import annotations

from pydantic import Field

from fleetlink.common.configfile import Section


class MetricsSection(Section):
    """Where the process serves ``/metrics`` and ``/health``."""

    listen: str = Field(default="127.0.0.1:9464", description="host:port serving /metrics and /health")
