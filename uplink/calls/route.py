"""One decoded record of a service or action mapping: convert, plan, forward to its site, and
— when the call cannot go out — write its final outcome to Kafka itself.

A record is settled (its offset may be committed) when the robot's repeater acknowledged the
call (``applied``, ``duplicate``, ``expired``, ``rejected``: from then on the outcome comes
from the site), or when its outcome was written here: the robot is at no known site
(``unavailable``), the deadline passed before a site acknowledged (``expired``).
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable
from typing import Literal

from fleetlink.uplink.calls.convert import CallTypes
from fleetlink.uplink.calls.mapping import ActionMapping, ServiceMapping
from fleetlink.uplink.calls.outcomes import OutcomeWriter
from fleetlink.uplink.calls.plan import CallForward, plan_call
from fleetlink.uplink.commands.decode import DecodedValue
from fleetlink.uplink.commands.forwarder import Forwarder
from fleetlink.uplink.commands.plan import CommandRecord
from fleetlink.wire.calls import CallKind, Outcome

log = logging.getLogger(__name__)

Role = Literal["service", "goal", "cancel"]
_OUTCOME = {"service": "reply", "goal": "result", "cancel": "cancel"}
_PART = {"service": "_Request", "goal": "_Goal"}


class CallRoute:
    """Turns a decoded request, goal or cancel record into a call, sends it to the robot's site, and gives
    the outcome to write when it cannot go out."""

    def __init__(
        self,
        types: CallTypes,
        forwarder: Forwarder,
        writer: OutcomeWriter,
        *,
        site_of: Callable[[str], str | None],
        clock: Callable[[], float] = time.time,
        stopping: Callable[[], bool] = lambda: False,
    ) -> None:
        self._types = types
        self._forwarder = forwarder
        self._writer = writer
        self._site_of = site_of
        self._clock = clock
        self._stopping = stopping
        self.forwarded = 0
        self.unrouted = 0

    def convert(self, role: Role, mapping: ServiceMapping | ActionMapping, decoded: DecodedValue) -> bytes:
        """The CDR payload of a request or goal (raises ``UndecodableValueError``); b"" for a cancel."""
        if role == "cancel":
            return b""
        return self._types.to_cdr(f"{mapping.type}{_PART[role]}", decoded)

    def plan(
        self,
        role: Role,
        record: CommandRecord,
        mapping: ServiceMapping | ActionMapping,
        decoded: DecodedValue,
    ) -> CallForward:
        """Raises ``RoutingError`` or ``UndecodableValueError`` (both dead letters)."""
        payload = self.convert(role, mapping, decoded)
        now_ms = int(self._clock() * 1000)
        kind: CallKind = role
        return plan_call(kind, record, mapping, decoded.record, payload, now_ms=now_ms, site_of=self._site_of)

    def send(self, forward: CallForward) -> tuple[bool, Outcome | None]:
        """Forward: (settled, the outcome the uplink must write itself). (False, None): stopping."""
        env = forward.envelope
        now_ms = int(self._clock() * 1000)
        if forward.site is None:
            self.unrouted += 1
            return False, self._final(
                forward, "unavailable", f"robot {env.robot} is registered at no site", now_ms
            )
        if now_ms >= env.deadline_ms:
            late = (now_ms - env.deadline_ms) / 1000
            detail = f"the deadline passed {late:.1f} s before the uplink read it"
            return False, self._final(forward, "expired", detail, now_ms)
        self.forwarded += 1
        settled, detail = self._forwarder.send_call(forward.key_expr, forward.site, env)
        if settled or self._stopping():
            return settled, None
        return False, self._final(forward, "expired", detail, int(self._clock() * 1000))

    @staticmethod
    def _final(forward: CallForward, status: str, detail: str, now_ms: int) -> Outcome:
        env = forward.envelope
        if env.kind == "cancel":
            status = {"expired": "cancel-timeout", "unavailable": "cancel-unavailable"}[status]
        return Outcome(
            _OUTCOME[env.kind],  # type: ignore[arg-type]
            env.call_id,
            env.robot,
            env.mapping,
            status,
            now_ms,
            detail,
            None,
            env.issued_at_ms,
        )
