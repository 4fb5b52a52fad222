"""Zenoh session configuration for a ROS peer, and opening it.

rmw_zenoh nodes run as ``peer`` sessions connected to a router on ``tcp/localhost:7447``,
listening on a random loopback port, with multicast scouting off and timestamping on
(rmw_zenoh.md §1). :func:`ros_session_config` gives the same defaults for whatever the user did
not set on the command line or in a config file.
"""

from __future__ import annotations

import json
import logging
from typing import Any

import zenoh

from fleetlink.common.errors import ConfigError
from fleetlink.common.zenoh_options import ZenohOptions

DEFAULT_ROUTER = "tcp/127.0.0.1:7447"


def ros_session_config(options: ZenohOptions | None = None) -> zenoh.Config:
    """A session config that behaves like an rmw_zenoh node's unless ``options`` say otherwise."""
    options = options or ZenohOptions()
    if options.config_file is None:
        mode = options.mode or "peer"
        options = options.with_defaults(
            mode=mode,
            connect=(DEFAULT_ROUTER,),
            listen=("tcp/127.0.0.1:0",) if mode == "peer" else (),
        )
    conf = options.to_config()
    if options.config_file is None:
        conf.insert_json5("timestamping/enabled", json.dumps(True))
    return conf


def open_session(config: zenoh.Config) -> zenoh.Session:
    """Open a session; zenoh's own errors become a ConfigError naming the cause."""
    try:
        return zenoh.open(config)
    except zenoh.ZError as exc:
        raise ConfigError(f"cannot open zenoh session: {exc}") from None


def undeclare(entity: Any, log: logging.Logger, what: str, name: str) -> None:
    """Undeclare a zenoh entity; an error (the session is closed already) is only logged."""
    try:
        entity.undeclare()
    except zenoh.ZError as exc:
        log.debug("%s undeclare on %s: %s", what, name, exc)
