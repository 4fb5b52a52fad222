"""Commands arriving over Zenoh: each envelope's signature is checked first (only the cloud's key
makes a command, ``fleetlink.wire.command_auth``: a forged one is refused, counted and never
read further nor journalled); then it is decoded, converted to CDR, offered to the schedule,
journalled (fsynced before the answer) and answered with what the repeater did (``applied``,
``duplicate``, ``expired``, ``superseded``, ``rejected``, ``need-schema``)."""

from __future__ import annotations

import logging
from collections.abc import Callable, Mapping

import zenoh
from cryptography.hazmat.primitives.asymmetric.ed25519 import Ed25519PublicKey

from fleetlink.common.ratelimit import LogLimiter
from fleetlink.repeater.converter import Converter
from fleetlink.repeater.errors import ConversionError, JournalError
from fleetlink.repeater.schedule import Change, Offer, Publish
from fleetlink.repeater.shared import Shared, to_command
from fleetlink.repeater.signed import signed_payload
from fleetlink.repeater.statuses import record
from fleetlink.wire.commands import CommandEnvelope, CommandReply, Result, decode_envelope, encode_reply
from fleetlink.wire.errors import EnvelopeError
from fleetlink.wire.keys import command_key

log = logging.getLogger(__name__)

_RESULT: dict[Offer, Result] = {
    Offer.APPLIED: "applied",
    Offer.DUPLICATE: "duplicate",
    Offer.EXPIRED: "expired",
    Offer.SUPERSEDED: "superseded",
}


class Intake:
    """Takes command envelopes; ``publish(items, now)`` publishes an applied command at once."""

    def __init__(
        self,
        shared: Shared,
        converter: Converter,
        *,
        max_active: int,
        publish: Callable[[list[Publish], float], None],
        keys: Mapping[bytes, Ed25519PublicKey],
        on_forged: Callable[[str], None] = lambda _kind: None,
    ) -> None:
        self._shared = shared
        self._converter = converter
        self._max_active = max_active
        self._publish = publish
        self._keys = keys
        self._on_forged = on_forged
        self._limiter = LogLimiter(log)

    def on_query(self, query: zenoh.Query) -> None:
        """A Zenoh query on ``fleetlink/<site>/command/**`` (on a Zenoh thread)."""
        shared = self._shared
        data = signed_payload(
            query, shared, self._keys, what="command", on_forged=self._on_forged, limiter=self._limiter
        )
        if data is None:
            return
        try:
            if query.payload is None:
                raise EnvelopeError("command envelope", "the query carries no payload")
            env = decode_envelope(data)
        except EnvelopeError as exc:
            shared.stats.malformed += 1
            log.warning("refused a malformed command on %s: %s", query.key_expr, exc)
            query.reply_err(str(exc).encode())
            query.drop()
            return
        try:
            with shared.lock:
                shared.schedule.link_up()
                reply = self.accept(env)
            shared.poke.set()
            shared.store.sync()  # durable before the uplink may commit (outside the lock: fsyncs overlap)
        except JournalError as exc:
            log.error("cannot make command %s durable: %s", env.command_id, exc)
            query.reply_err(f"repeater state not durable: {exc.reason}".encode())
            query.drop()
            return
        # reply on this site's own key (a query for every site carries a wildcard; routers'
        # ACLs let a site answer only under fleetlink/<site>/**)
        query.reply(command_key(shared.site, env.robot, env.mapping), encode_reply(reply))
        query.drop()

    def accept(self, env: CommandEnvelope) -> CommandReply:
        """Apply one command envelope (call under the lock); publishes at once when applied."""
        shared = self._shared
        now = shared.clock()
        command = to_command(env)

        def reply(result: Result, detail: str = "") -> CommandReply:
            return CommandReply(env.command_id, env.robot, result, detail, shared.site, shared.id)

        if command.ident in shared.schedule.seen():
            shared.stats.duplicates += 1
            return reply("duplicate", "command id already applied")
        schema = env.schema or shared.store.schemas.get(env.schema_fp)
        if now < command.lease_until:
            try:
                own = self._converter.is_own_schema(env)
            except ConversionError as exc:
                problem = exc.reason
            else:
                if schema is None and not own:
                    shared.stats.need_schema += 1
                    return reply("need-schema", f"writer schema {env.schema_fp.hex()} unknown here")
                problem = self.check(env, schema)
            if problem:
                shared.stats.rejected += 1
                shared.schedule.remember(command)
                shared.store.command(env, now, ended=True)
                record(shared, [Change(command, "rejected", now, problem)])
                return reply("rejected", problem)
        outcome = shared.schedule.offer(command, now)
        if outcome.offer is Offer.DUPLICATE:
            shared.stats.duplicates += 1
            return reply("duplicate", outcome.detail)
        shared.store.command(
            env if schema is None else env.with_schema(schema), now, ended=outcome.offer is not Offer.APPLIED
        )
        if outcome.offer is Offer.APPLIED:
            shared.stats.applied += 1
        elif outcome.offer is Offer.EXPIRED:
            shared.stats.expired_on_arrival += 1
        else:
            shared.stats.superseded_on_arrival += 1
        record(shared, outcome.changes)
        self._publish(outcome.publish, now)
        return reply(_RESULT[outcome.offer], outcome.detail)

    def check(self, env: CommandEnvelope, schema: str | None) -> str:
        """Convert the command now (kept for its repeats); the reason it cannot be, or ''."""
        shared = self._shared
        current = {a.slot for a in shared.schedule.active()}
        if (env.robot, env.ros_topic) not in current and len(current) >= self._max_active:
            return f"too many active commands (max_active={self._max_active})"
        try:
            cdr = self._converter.to_cdr(env, schema)
        except ConversionError as exc:
            return exc.reason
        shared.cdr[env.command_id, env.robot] = (env, cdr)
        return ""
