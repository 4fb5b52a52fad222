"""The fleet console's section (``console:`` of the uplink's config)."""

from __future__ import annotations

from pathlib import Path

from pydantic import Field

from fleetlink.common.configfile import Section
from fleetlink.common.durations import Seconds


class ConsoleSection(Section):
    """Where the fleet web console listens, how operators sign in, and how often it polls the sites."""

    listen: str = Field(
        examples=["127.0.0.1:8490"],
        description="host:port the fleet web console listens on (HTTP; put TLS in front when exposed)",
    )
    token_env: str | None = Field(
        default="FLEETLINK_ADMIN_TOKEN",
        description="environment variable holding the access token: operators sign in with it, and it "
        "is sent to the sites' admin spaces (the same token as the edges' admin API)",
    )
    token_file: Path | None = Field(
        default=None, description="file holding the access token (wins over token_env)"
    )
    users_file: Path | None = Field(
        default=None,
        description="YAML file of named users with roles (viewer, operator, admin) and scrypt password "
        "hashes (fleetlink console hash-password); $FLEETLINK_CONSOLE_USERS_FILE when not set",
    )
    history_step: Seconds = Field(
        default=10.0,
        ge=1,
        le=600,
        description="how often the console samples each site for its charts (the last hour)",
    )
    session_ttl: Seconds = Field(
        default=8 * 3600.0,
        gt=0,
        description="how long a browser stays signed in (then the token is asked again)",
    )
    query_timeout: Seconds = Field(
        default=3.0, gt=0, le=60, description="how long to wait for the sites' answers over Zenoh"
    )
    poll_interval: Seconds = Field(
        default=1.0,
        ge=0.2,
        le=60,
        description="how often the pages refresh (rates are computed between polls)",
    )
