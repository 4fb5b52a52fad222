"""The WAN transport: one batch = one Zenoh query; the uplink's reply is the acknowledgement.

``ZenohTransport.send`` puts the batch as the payload of ``session.get(key, ...)`` with
``QueryTarget.BEST_MATCHING`` (one uplink instance takes it) and calls ``done(reply, error)``
exactly once, from a Zenoh thread, when the query is finished: with the first reply's bytes, or
with ``reply=None`` and the reason (an error reply, no uplink serving the key, or the timeout).
With ``Uplinks`` the key is the ingest key addressed to the uplink that takes the stream
(``edge.runtime.uplinks``); an uplink that did not answer is left out from then on.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable
from typing import Protocol

import zenoh

from fleetlink.edge.runtime.uplinks import Uplinks
from fleetlink.wire.keys import via_key

Done = Callable[[bytes | None, str | None], None]


class Transport(Protocol):
    """Carries one encoded batch to the uplink and reports its answer."""

    def send(self, payload: bytes, timeout_s: float, done: Done) -> None:
        """Send ``payload`` and call ``done(reply, error)`` exactly once: with the reply's bytes, or with
        ``None`` and the reason within about ``timeout_s`` seconds."""
        ...


class ZenohTransport:
    """Sends each batch as the payload of a Zenoh query on the uplink's ingest key."""

    def __init__(
        self, session: zenoh.Session, key: str, *, uplinks: Uplinks | None = None, route: str = ""
    ) -> None:
        self.session = session
        self.key = key
        self.uplinks = uplinks
        self.route = route

    def for_stream(self, stream: str) -> ZenohTransport:
        """The transport of one stream: its batches go to the uplink that takes the stream."""
        return ZenohTransport(self.session, self.key, uplinks=self.uplinks, route=stream)

    def send(self, payload: bytes, timeout_s: float, done: Done) -> None:
        """Query the key with ``payload`` (one uplink takes it); ``done`` runs once on a Zenoh thread with
        the first reply's bytes, or with ``None`` and the reason (an error reply, no uplink, the timeout)."""
        began = time.monotonic()
        uplinks = self.uplinks
        uplink = uplinks.route(self.route) if uplinks is not None else None
        key = via_key(self.key, uplink) if uplink is not None else self.key
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
                    else f"no uplink answered on {key}"
                )
                if uplinks is not None and uplink is not None:
                    uplinks.failed(uplink)  # gone (an uplink that answers, even "busy", stays)
            done(None, error)

        self.session.get(
            key,
            # run on Zenoh's thread: the default (indirect) starts a Python thread for every
            # query's handler, some 0.2 ms of the edge's CPU a batch; these two only take a lock
            # and put the answer on the sender's queue
            zenoh.handlers.Callback(on_reply, on_finished, indirect=False),
            payload=payload,
            target=zenoh.QueryTarget.BEST_MATCHING,
            timeout=timeout_s,
        )
