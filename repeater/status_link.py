"""Status events to the uplink, and the pulse of the link to it (for the dead-man).

Pending events go out in batches (gathered for up to ``linger`` seconds) as a Zenoh query on
``fleetlink/<site>/command-status/<id>``; the uplink answers once Kafka has them, and only then
are they acknowledged (``on_acked``), so delivery is at-least-once. With nothing pending, an
empty batch every ``heartbeat`` seconds asks the uplink whether it is there. Any answer from
the uplink (even "not written now": Kafka may be down) reports the link up; a timeout or an
error reply reports it down (``on_link``): that is what the dead-man watches.
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable
from types import TracebackType
from typing import Any

import zenoh

from fleetlink.common.ratelimit import LogLimiter
from fleetlink.wire.commands import StatusBatch, decode_status_ack, encode_status_batch
from fleetlink.wire.errors import EnvelopeError
from fleetlink.wire.keys import site_prefix

log = logging.getLogger(__name__)

MAX_BATCH = 200
LinkCallback = Callable[[bool], None]
AckCallback = Callable[[list[int]], None]


def status_key(site: str, repeater_id: str) -> str:
    """The key the uplink takes a repeater's status batches on."""
    return f"{site_prefix(site)}/command-status/{repeater_id}"


class StatusLink:
    """Sends pending events to the uplink in batches from its own thread, and reports whether the uplink
    answers (``on_link``) and which events it took (``on_acked``)."""

    def __init__(
        self,
        session: zenoh.Session,
        site: str,
        repeater_id: str,
        *,
        heartbeat: float,
        timeout: float,
        on_link: LinkCallback,
        on_acked: AckCallback,
        linger: float = 0.1,
        key: str | None = None,
        encode: Callable[[tuple[Any, ...]], bytes] | None = None,
        heartbeats: bool = True,
    ) -> None:
        """``key`` and ``encode`` send other events than command statuses (call outcomes) the
        same way; without ``heartbeats`` nothing is sent while nothing is pending."""
        self._session = session
        self._site = site
        self._id = repeater_id
        self._key = key or status_key(site, repeater_id)
        self._encode = encode or self._encode_statuses
        self._heartbeats = heartbeats
        self._heartbeat = heartbeat
        self._timeout = timeout
        self._on_link = on_link
        self._on_acked = on_acked
        self._linger = linger
        self._oldest: float | None = None  # when the oldest unsent event was submitted (monotonic)
        self._pending: dict[int, Any] = {}
        self._cond = threading.Condition()
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._limiter = LogLimiter(log)
        self.sent = 0
        self.failures = 0

    def start(self) -> StatusLink:
        """Start the ``repeater-status`` thread; returns the link."""
        self._stop.clear()
        self._thread = threading.Thread(target=self._run, name="repeater-status", daemon=True)
        self._thread.start()
        return self

    def stop(self) -> None:
        """Stop the thread, waiting at most the query timeout plus 5 s; pending events stay unsent."""
        self._stop.set()
        with self._cond:
            self._cond.notify_all()
        if self._thread is not None:
            self._thread.join(self._timeout + 5)
            self._thread = None

    def __enter__(self) -> StatusLink:
        return self.start()

    def __exit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        self.stop()

    def submit(self, number: int, event: Any) -> None:
        """Queue event ``number`` for the next batch (an event queued under the same number is replaced)."""
        with self._cond:
            self._pending[number] = event
            if self._oldest is None:
                self._oldest = time.monotonic()
            self._cond.notify_all()

    def pending(self) -> int:
        """How many events wait for the uplink's acknowledgement."""
        with self._cond:
            return len(self._pending)

    # -- loop -----------------------------------------------------------------------------

    def _run(self) -> None:
        backoff = 0.0
        while not self._stop.is_set():
            with self._cond:
                if backoff > 0 or not self._pending:
                    self._cond.wait(backoff if backoff > 0 else self._heartbeat)
                if not self._heartbeats and not self._pending:
                    continue
                # linger a little so events close in time share one batch (one query on the WAN)
                while (
                    self._pending
                    and self._oldest is not None
                    and len(self._pending) < MAX_BATCH
                    and not self._stop.is_set()
                ):
                    left = self._oldest + self._linger - time.monotonic()
                    if left <= 0:
                        break
                    self._cond.wait(left)
                if self._stop.is_set():
                    return
                numbers = sorted(self._pending)[:MAX_BATCH]
                events = tuple(self._pending[n] for n in numbers)
                self._oldest = None
            if self._send(events):
                backoff = 0.0
                if numbers:
                    with self._cond:
                        for n in numbers:
                            self._pending.pop(n, None)
                        if self._pending and self._oldest is None:
                            self._oldest = time.monotonic()
                    self._on_acked(numbers)
            else:
                backoff = min(max(backoff * 2, 0.2), self._heartbeat)

    def _encode_statuses(self, events: tuple[Any, ...]) -> bytes:
        return encode_status_batch(StatusBatch(self._id, self._site, events))

    def _send(self, events: tuple[Any, ...]) -> bool:
        payload = self._encode(events)
        problem = "no uplink answered"
        contact = False
        try:
            replies = self._session.get(
                self._key, payload=payload, timeout=self._timeout, target=zenoh.QueryTarget.BEST_MATCHING
            )
            for reply in replies:
                if reply.ok is None:
                    # zenoh reports a timeout as an error reply too: no proof of an uplink
                    err = reply.err
                    problem = f"error reply: {err.payload.to_bytes()[:200]!r}" if err else "error reply"
                    continue
                contact = True  # an uplink answered, even if it could not take the events now
                ack = decode_status_ack(reply.ok.payload.to_bytes())
                if ack.accepted == len(events):
                    self.sent += len(events)
                    self._on_link(True)
                    return True
                problem = f"uplink accepted {ack.accepted} of {len(events)}: {ack.detail}"
        except (zenoh.ZError, EnvelopeError) as exc:
            problem = str(exc)
        self.failures += 1
        if events:
            self._limiter.log(
                logging.WARNING, "status", "status batch of %d not acknowledged: %s", len(events), problem
            )
        self._on_link(contact)
        return False
