"""Send one command to its site (a Zenoh query) until a repeater takes it, or its lease ends.

A repeater's reply *settles* the forward when it says ``applied``, ``duplicate`` (applied
before: the re-delivery after an uplink crash), ``expired``, ``superseded`` or ``rejected``.
``need-schema`` is answered at once by sending the envelope again with the writer schema.
No reply (site unreachable, no repeater there), an error reply or a timeout are tried again
with exponential backoff (100 ms doubling to 2 s) until the lease ends: then the forward gives
up and the command is reported ``expired``.

Envelopes carry the writer schema's JSON only until the site has acknowledged one command
with that schema: later ones carry just its fingerprint. A command for a robot of unknown site
(a query to every site) goes lean once any site has the schema; a site that answers
``need-schema`` then gets the full envelope at its own key.
"""

from __future__ import annotations

import logging
import threading
from collections.abc import Callable
from dataclasses import dataclass, field, replace

import zenoh

from fleetlink.common.ratelimit import LogLimiter
from fleetlink.uplink.commands.plan import Forward
from fleetlink.uplink.commands.signing import CommandSigner
from fleetlink.wire.calls import CallEnvelope, encode_call
from fleetlink.wire.commands import SETTLED, CommandReply, decode_reply, encode_envelope
from fleetlink.wire.errors import EnvelopeError
from fleetlink.wire.keys import command_key

log = logging.getLogger(__name__)

FIRST_BACKOFF_S = 0.1
MAX_BACKOFF_S = 2.0


@dataclass
class ForwardResult:
    """How one forward ended: settled or not, the repeaters' replies, why it did not settle, and how many
    queries it took."""

    forward: Forward
    settled: bool
    replies: list[CommandReply] = field(default_factory=list)
    detail: str = ""
    attempts: int = 0


class Forwarder:
    """Sends signed command and call envelopes to their sites as Zenoh queries, again and again until a
    repeater settles them."""

    def __init__(
        self,
        session: zenoh.Session,
        *,
        query_timeout: float = 5.0,
        clock: Callable[[], float],
        stop: threading.Event,
        signer: CommandSigner,
    ) -> None:
        self._session = session
        self._signer = signer
        self._timeout = query_timeout
        self._clock = clock
        self._stop = stop
        self._known: set[tuple[str, bytes]] = set()  # (site, schema fingerprint) the site acknowledged
        self._lock = threading.Lock()
        self._limiter = LogLimiter(log)

    def send(self, fwd: Forward) -> ForwardResult:
        """Send a command to its site (every site when unknown) until a repeater settles it, its lease ends
        or the uplink stops; the schema text is left out where a site has acknowledged it."""
        full = fwd.envelope
        fp = full.schema_fp
        with self._lock:
            if fwd.site is None:  # every site: lean once any site has the schema (the rest ask)
                lean = any(known == fp for _site, known in self._known)
            else:
                lean = (fwd.site, fp) in self._known
        env = full.without_schema() if lean else full
        result = ForwardResult(fwd, settled=False)
        delay = FIRST_BACKOFF_S
        target = zenoh.QueryTarget.ALL if fwd.site is None else zenoh.QueryTarget.BEST_MATCHING
        while not self._stop.is_set():
            remaining = full.lease_until_ms / 1000 - self._clock()
            if remaining <= 0:
                result.detail = f"no site acknowledged before the lease ended ({result.detail or 'no reply'})"
                return result
            timeout = min(self._timeout, max(remaining, 0.05))
            result.attempts += 1
            replies, problem = self._query(fwd.key_expr, encode_envelope(env), target, timeout, fwd.site)
            needy = [r for r in replies if r.result == "need-schema"] if env.schema is None else []
            if needy and fwd.site is not None:
                env = full  # the full envelope, with the schema: at once
                continue
            if needy:  # only the sites that lack the schema get it again, each at its own key
                replies = [r for r in replies if r.result != "need-schema"]
                for reply in needy:
                    if reply.site:
                        more, _ = self._query(
                            command_key(reply.site, full.robot, full.mapping),
                            encode_envelope(full),
                            zenoh.QueryTarget.BEST_MATCHING,
                            timeout,
                            reply.site,
                        )
                        replies += more
            result.replies = replies
            settled = [r for r in replies if r.result in SETTLED]
            if settled:
                with self._lock:
                    self._known.update((r.site, fp) for r in settled if r.site)
                result.settled = True
                return result
            result.detail = problem or "; ".join(f"{r.result}: {r.detail}" for r in replies) or "no reply"
            self._limiter.log(
                logging.WARNING,
                f"forward:{fwd.site}",
                "command %s for %s not acknowledged yet (%s); retrying",
                env.command_id,
                fwd.key_expr,
                result.detail,
            )
            self._stop.wait(delay)
            delay = min(delay * 2, MAX_BACKOFF_S)
        result.detail = "uplink stopping"
        return result

    def send_call(self, key_expr: str, site: str, env: CallEnvelope) -> tuple[bool, str]:
        """Send a call envelope to ``site`` until its repeater settles it or its deadline passes:
        (settled, why not)."""
        payload = encode_call(env)
        delay, detail = FIRST_BACKOFF_S, ""
        while not self._stop.is_set():
            remaining = env.deadline_ms / 1000 - self._clock()
            if remaining <= 0:
                return False, f"no site acknowledged before the deadline ({detail or 'no reply'})"
            timeout = min(self._timeout, max(remaining, 0.05))
            replies, problem = self._query(key_expr, payload, zenoh.QueryTarget.BEST_MATCHING, timeout, site)
            if any(r.result in SETTLED for r in replies):
                return True, ""
            detail = problem or "; ".join(f"{r.result}: {r.detail}" for r in replies) or "no reply"
            self._limiter.log(
                logging.WARNING,
                f"call:{site}",
                "call %s for %s not acknowledged yet (%s); retrying",
                env.call_id,
                key_expr,
                detail,
            )
            self._stop.wait(delay)
            delay = min(delay * 2, MAX_BACKOFF_S)
        return False, "uplink stopping"

    def _query(
        self, key: str, payload: bytes, target: zenoh.QueryTarget, timeout: float, site: str | None
    ) -> tuple[list[CommandReply], str]:
        """Send one signed envelope; each reply's site is the one its key proves, not what it says."""
        replies: list[CommandReply] = []
        problems: list[str] = []
        try:
            for reply in self._session.get(
                key,
                payload=payload,
                attachment=self._signer.attachment(payload, site),
                target=target,
                timeout=timeout,
                consolidation=zenoh.ConsolidationMode.NONE,
            ):
                if reply.ok is not None:
                    try:
                        decoded = decode_reply(reply.ok.payload.to_bytes())
                    except EnvelopeError as exc:
                        problems.append(str(exc))
                        continue
                    replies.append(replace(decoded, site=site_of_key(str(reply.ok.key_expr))))
                elif reply.err is not None:
                    text = reply.err.payload.to_bytes()[:300].decode("utf-8", "replace")
                    problems.append(f"site refused: {text}")
        except zenoh.ZError as exc:
            problems.append(f"query failed: {exc}")
        return replies, "; ".join(problems)


def site_of_key(key: str) -> str:
    """The site of a reply key ``fleetlink/<site>/...`` (routers let a site answer only there)."""
    parts = key.split("/", 2)
    return parts[1] if len(parts) >= 2 and parts[0] == "fleetlink" else ""
