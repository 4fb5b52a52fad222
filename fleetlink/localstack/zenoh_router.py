"""A Zenoh router on loopback: an eclipse-zenoh session in ``router`` mode (zenohd's Rust core)."""

from __future__ import annotations

import json
from types import TracebackType
from typing import Any

import zenoh

from fleetlink.localstack.process import free_port


class ZenohRouter:
    """``ZenohRouter(port)`` listens on tcp/127.0.0.1:port; ``connect`` joins other routers."""

    def __init__(
        self,
        port: int | None = None,
        *,
        connect: tuple[str, ...] = (),
        extra: dict[str, Any] | None = None,
    ) -> None:
        self.port = port or free_port()
        self.connect = connect
        self.extra = extra or {}
        self.session: zenoh.Session | None = None

    @property
    def endpoint(self) -> str:
        """The router's listen endpoint, ``tcp/127.0.0.1:<port>``."""
        return f"tcp/127.0.0.1:{self.port}"

    def config(self) -> zenoh.Config:
        """The router's session config: router mode, its endpoints, no multicast scouting, timestamps on."""
        conf = zenoh.Config()
        conf.insert_json5("mode", '"router"')
        conf.insert_json5("listen/endpoints", json.dumps([self.endpoint]))
        conf.insert_json5("connect/endpoints", json.dumps(list(self.connect)))
        conf.insert_json5("scouting/multicast/enabled", "false")
        conf.insert_json5("timestamping/enabled", "true")
        for key, value in self.extra.items():
            conf.insert_json5(key, json.dumps(value))
        return conf

    def start(self) -> ZenohRouter:
        """Open the router session unless it is open already; returns ``self``."""
        if self.session is None:
            self.session = zenoh.open(self.config())
        return self

    def stop(self) -> None:
        """Close the router session if it is open."""
        if self.session is not None:
            self.session.close()
            self.session = None

    def __enter__(self) -> ZenohRouter:
        return self.start()

    def __exit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        self.stop()
