"""The repeater's one config model (``fleetlink repeater run -c repeater.yaml``).

::

    repeater:
      site: warehouse-a              # serves fleetlink/<site>/command/**
      state_dir: /var/lib/fleetlink/repeater
      command_keys: [/etc/fleetlink/command-signing.pem]   # the uplink's public key
      dead_man: 30s                  # optional cap; default: each command's own lease
    ros: {domain_id: 0, distro: jazzy}      # message_paths: [your own packages' folders]
    zenoh: {mode: peer, connect: [tcp/127.0.0.1:7447]}   # the site router

Durations are ``"250ms"``, ``"1s"``, ``"2m"``, ``"1h"`` or a number of seconds
(:mod:`fleetlink.common.durations`).
"""

from __future__ import annotations

import socket
from pathlib import Path

from pydantic import Field

from fleetlink.common.configfile import Section
from fleetlink.common.durations import PositiveSeconds
from fleetlink.common.metrics_config import MetricsSection
from fleetlink.common.names import KeyChunk, Site, host_id
from fleetlink.common.zenoh_options import ZenohSection
from fleetlink.schemas.typestore import Distro


def default_repeater_id() -> str:
    """The host name, cut to a valid key-expression chunk."""
    return host_id(socket.gethostname(), "repeater")


class RepeaterSection(Section):
    """The ``repeater:`` section: the site served, the state directory, the trusted command keys and
    the timing of the link to the uplink."""

    site: Site = Field(examples=["warehouse-a"])
    state_dir: Path
    command_keys: list[Path] = Field(
        min_length=1,
        description="public keys (PEM) of the uplink's command signing key: a command not signed "
        "by one of them for this site is refused unread (fleetlink certs command-key)",
    )
    id: KeyChunk = Field(default_factory=default_repeater_id)
    """Names this repeater in status batches (one key chunk)."""
    dead_man: PositiveSeconds | None = None
    """Stop repeating when the uplink has been unreachable this long (capped by each command's lease)."""
    heartbeat: PositiveSeconds = 2.0
    """How often the repeater checks its link to the uplink when it has no status to send."""
    status_timeout: PositiveSeconds = 5.0
    """How long one status batch (or heartbeat) may wait for the uplink's answer."""
    max_active: int = Field(default=10_000, ge=1, le=1_000_000)
    """Active commands at most (one per robot and ROS topic); more are rejected."""


class RosSection(Section):
    """The ``ros:`` section: the ROS domain id, the distro and the folders of extra message packages."""

    domain_id: int = Field(default=0, ge=0, le=232)
    distro: Distro = "jazzy"
    """Decides type hashes (and so the data keys robots subscribe on)."""
    message_paths: list[Path] = []
    """Folders of your own packages the commands use; the standard ones and irobot_create_msgs ship
    with fleetlink (a folder here replaces a package of its name)."""


class RepeaterConfig(Section):
    """A repeater's whole config file: the ``repeater``, ``ros`` and ``zenoh`` sections and the optional
    ``metrics`` one."""

    repeater: RepeaterSection
    ros: RosSection = RosSection()
    zenoh: ZenohSection = ZenohSection()
    metrics: MetricsSection | None = None
    """Prometheus ``/metrics`` and ``/health`` over HTTP; off when absent (docs/metrics.md)."""
