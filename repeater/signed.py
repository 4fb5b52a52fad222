"""The first step for every query the cloud makes of a repeater (commands, calls): its signature."""

from __future__ import annotations

import logging
from collections.abc import Callable, Mapping

import zenoh
from cryptography.hazmat.primitives.asymmetric.ed25519 import Ed25519PublicKey

from fleetlink.common.ratelimit import LogLimiter
from fleetlink.repeater.shared import Shared
from fleetlink.wire.command_auth import verify_envelope
from fleetlink.wire.errors import CommandAuthError


def signed_payload(
    query: zenoh.Query,
    shared: Shared,
    keys: Mapping[bytes, Ed25519PublicKey],
    *,
    what: str,
    on_forged: Callable[[str], None],
    limiter: LogLimiter,
) -> bytes | None:
    """The payload of ``query`` (empty when it has none) if the cloud signed it; otherwise None,
    after the forgery was counted, logged and refused (it is never read further)."""
    payload = query.payload
    data = payload.to_bytes() if payload is not None else b""
    try:
        attachment = query.attachment
        verify_envelope(data, attachment.to_bytes() if attachment is not None else None, shared.site, keys)
    except CommandAuthError as exc:
        shared.stats.forged += 1
        on_forged(exc.kind)
        limiter.log(logging.WARNING, f"forged:{exc.kind}", f"refused a {what} on %s: %s", query.key_expr, exc)
        query.reply_err(str(exc).encode())
        query.drop()
        return None
    return data
