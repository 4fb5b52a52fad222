"""Small helpers shared by the test suites: wait on a condition, pick a free port.

Tests never ``time.sleep`` to synchronise; they wait for a condition with a deadline::

    wait_until(lambda: len(received) == 10, timeout=5, message="10 samples received")
"""

from __future__ import annotations

import json
import time
from collections.abc import Callable

import zenoh

from fleetlink.localstack.process import free_port

__all__ = ["free_port", "wait_until", "zenoh_peer_config"]


def wait_until(
    pred: Callable[[], object],
    timeout: float = 10.0,
    interval: float = 0.02,
    message: str = "",
) -> None:
    """Poll ``pred`` until it returns something truthy; fail the test after ``timeout`` seconds.

    The predicate is evaluated once more at the deadline, so a condition that became true
    while the last interval elapsed still passes. On timeout an AssertionError is raised
    carrying ``message`` and the elapsed time.
    """
    start = time.monotonic()
    deadline = start + timeout
    while True:
        if pred():
            return
        now = time.monotonic()
        if now >= deadline:
            break
        time.sleep(min(interval, max(deadline - now, 0.0)))  # ok-sleep: the poll interval of wait_until
    if pred():
        return
    what = message or getattr(pred, "__name__", "condition")
    raise AssertionError(f"timed out after {time.monotonic() - start:.2f}s waiting for: {what}")


def zenoh_peer_config(endpoint: str, mode: str = "peer") -> zenoh.Config:
    """A session config that joins the router at ``endpoint`` like an rmw_zenoh node does:
    peer (or client) mode, loopback listener, no multicast scouting, timestamping on."""
    conf = zenoh.Config()
    conf.insert_json5("mode", json.dumps(mode))
    conf.insert_json5("connect/endpoints", json.dumps([endpoint]))
    conf.insert_json5("listen/endpoints", json.dumps(["tcp/127.0.0.1:0"] if mode == "peer" else []))
    conf.insert_json5("scouting/multicast/enabled", "false")
    conf.insert_json5("timestamping/enabled", "true")
    return conf
