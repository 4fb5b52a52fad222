"""The WAN transport: one batch = one Zenoh query; the uplink's reply is the acknowledgement.

``ZenohTransport.send`` puts the batch as the payload of ``session.get(ingest_key, ...)`` with
``QueryTarget.BEST_MATCHING`` (one uplink instance takes it) and calls ``done(reply, error)``
exactly once, from a Zenoh thread, when the query is finished: with the first reply's bytes, or
with ``reply=None`` and the reason (an error reply, no uplink serving the key, or the timeout).
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable
from typing import Protocol

import zenoh

Done = Callable[[bytes | None, str | None], None]


class Transport(Protocol):
    """Carries one encoded batch to the uplink and reports its answer."""

    def send(self, payload: bytes, timeout_s: float, done: Done) -> None:
        """Send ``payload`` and call ``done(reply, error)`` exactly once: with the reply's bytes, or with
        ``None`` and the reason within about ``timeout_s`` seconds."""
        ...


class ZenohTransport:
    """Sends each batch as the payload of a Zenoh query on the uplink's ingest key."""

    def __init__(self, session: zenoh.Session, key: str) -> None:
        self.session = session
        self.key = key

    def send(self, payload: bytes, timeout_s: float, done: Done) -> None:
        """Query ``key`` with ``payload`` (one uplink takes it); ``done`` runs once on a Zenoh thread with
        the first reply's bytes, or with ``None`` and the reason (an error reply, no uplink, the timeout)."""
        began = time.monotonic()
        lock = threading.Lock()
        got: dict[str, bytes | str] = {}

        def on_reply(reply: zenoh.Reply) -> None:
            with lock:
                if "reply" in got:
                    return
                if reply.ok is not None:
                    got["reply"] = reply.ok.payload.to_bytes()
                elif reply.err is not None:
                    got.setdefault(
                        "error",
                        "uplink error reply: " + reply.err.payload.to_bytes().decode("utf-8", "replace"),
                    )

        def on_finished() -> None:
            with lock:
                reply = got.get("reply")
                error = got.get("error")
            if isinstance(reply, bytes):
                done(reply, None)
                return
            if not isinstance(error, str):
                waited = time.monotonic() - began
                error = (
                    f"no acknowledgement within {timeout_s:g} s"
                    if waited >= timeout_s * 0.9
                    else f"no uplink answered on {self.key}"
                )
            done(None, error)

        self.session.get(
            self.key,
            # run on Zenoh's thread: the default (indirect) starts a Python thread for every
            # query's handler, some 0.2 ms of the edge's CPU a batch; these two only take a lock
            # and put the answer on the sender's queue
            zenoh.handlers.Callback(on_reply, on_finished, indirect=False),
            payload=payload,
            target=zenoh.QueryTarget.BEST_MATCHING,
            timeout=timeout_s,
        )
