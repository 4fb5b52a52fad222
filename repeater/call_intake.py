"""Service calls and action goals arriving over Zenoh (``fleetlink/<site>/call/**``).

Like commands: the signature is checked first (only the cloud makes calls; a forged one is
refused, counted, never read further), then the envelope is decoded, checked against what
this repeater has seen (each (kind, id, robot) is made once: a re-delivery is a
``duplicate``), journalled (fsynced before the answer) and answered ``applied``; only then does
it run (:mod:`repeater.call_runner`). A call whose deadline has passed is answered
``expired``, one whose type this repeater does not know ``rejected``; both also become a
final outcome for Kafka.
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Mapping
from typing import TYPE_CHECKING

import zenoh
from cryptography.hazmat.primitives.asymmetric.ed25519 import Ed25519PublicKey

from fleetlink.common.ratelimit import LogLimiter
from fleetlink.repeater.call_store import CallStore, ident
from fleetlink.repeater.errors import JournalError
from fleetlink.repeater.shared import Shared
from fleetlink.repeater.signed import signed_payload
from fleetlink.wire.calls import CallEnvelope, Outcome, call_key, decode_call
from fleetlink.wire.commands import CommandReply, Result, encode_reply
from fleetlink.wire.errors import EnvelopeError

if TYPE_CHECKING:
    from rosbags.typesys.store import Typestore

log = logging.getLogger(__name__)

OUTCOME_KIND = {"service": "reply", "goal": "result", "cancel": "cancel"}


def known_type(ts: Typestore, env: CallEnvelope) -> bool:
    """Whether this repeater's type store has the messages ``env`` needs."""
    part = "_Request" if env.kind == "service" else "_Goal"
    return f"{env.ros_type}{part}" in ts.fielddefs


def final_outcome(env: CallEnvelope, status: str, detail: str, at_ms: int) -> Outcome:
    """The outcome that ends ``env`` without running it (expired, rejected, restarted)."""
    if env.kind == "cancel":
        status = {"expired": "cancel-timeout", "rejected": "cancel-rejected"}.get(status, "cancel-error")
    return Outcome(
        OUTCOME_KIND[env.kind],  # type: ignore[arg-type]
        env.call_id,
        env.robot,
        env.mapping,
        status,
        at_ms,
        detail,
        None,
        env.issued_at_ms,
    )


class CallIntake:
    """Takes call envelopes from Zenoh queries: refuses forged and malformed ones,
    journals and answers the rest, and hands the applied ones to the runner."""

    def __init__(
        self,
        shared: Shared,
        store: CallStore,
        typestore: Typestore,
        *,
        run: Callable[[CallEnvelope], None],
        emit: Callable[[Outcome, bool], None],
        keys: Mapping[bytes, Ed25519PublicKey],
        on_forged: Callable[[str], None] = lambda _kind: None,
    ) -> None:
        self._shared = shared
        self._store = store
        self._ts = typestore
        self._run = run
        self._emit = emit
        self._keys = keys
        self._on_forged = on_forged
        self._limiter = LogLimiter(log)
        self.accepted = 0
        self.duplicates = 0

    def on_query(self, query: zenoh.Query) -> None:
        """Check, journal (fsynced) and answer one call query; then run the call or emit its final outcome.

        A call that cannot be made durable is answered with an error and not run.
        """
        shared = self._shared
        data = signed_payload(
            query, shared, self._keys, what="call", on_forged=self._on_forged, limiter=self._limiter
        )
        if data is None:
            return
        try:
            env = decode_call(data)
        except EnvelopeError as exc:
            shared.stats.malformed += 1
            self._limiter.log(
                logging.WARNING, "malformed", "refused a malformed call on %s: %s", query.key_expr, exc
            )
            query.reply_err(str(exc).encode())
            query.drop()
            return
        try:
            with shared.lock:
                result, detail, final = self.accept(env)
            self._store.sync()  # durable before the uplink may commit
        except JournalError as exc:
            log.error("cannot make call %s durable: %s", env.call_id, exc)
            query.reply_err(f"repeater state not durable: {exc.reason}".encode())
            query.drop()
            return
        reply = CommandReply(env.call_id, env.robot, result, detail, shared.site, shared.id)
        query.reply(call_key(shared.site, env.robot, env.mapping), encode_reply(reply))
        query.drop()
        if final is not None:
            self._emit(final, True)
        elif result == "applied":
            self._run(env)

    def accept(self, env: CallEnvelope) -> tuple[Result, str, Outcome | None]:
        """What to answer, and the final outcome when the call will not run (under the lock)."""
        now = self._shared.clock()
        if ident(env) in self._store.calls:
            self.duplicates += 1
            return "duplicate", "call id already taken", None
        self._store.accept(env, now)
        now_ms = int(now * 1000)
        if now_ms >= env.deadline_ms:
            late = (now_ms - env.deadline_ms) / 1000
            detail = f"the deadline passed {late:.1f} s before the call reached the site"
            return "expired", detail, final_outcome(env, "expired", detail, now_ms)
        if not known_type(self._ts, env):
            detail = f"type {env.ros_type} is unknown at this site (ros.message_paths)"
            return "rejected", detail, final_outcome(env, "rejected", detail, now_ms)
        self.accepted += 1
        return "applied", "", None
