"""Signed command envelopes: only the uplink's key, for this site (or every site), passes."""

from __future__ import annotations

import pytest
from cryptography.hazmat.primitives.asymmetric.ed25519 import Ed25519PrivateKey

from fleetlink.wire.command_auth import key_id, sign_envelope, verify_envelope
from fleetlink.wire.errors import CommandAuthError

KEY = Ed25519PrivateKey.generate()
OTHER = Ed25519PrivateKey.generate()
TRUSTED = {key_id(KEY.public_key()): KEY.public_key()}
ENVELOPE = b"FLC\x01\x00envelope bytes"


def test_a_signed_envelope_passes_at_its_site_and_for_every_site() -> None:
    verify_envelope(ENVELOPE, sign_envelope(ENVELOPE, "site-a", KEY), "site-a", TRUSTED)
    verify_envelope(ENVELOPE, sign_envelope(ENVELOPE, "*", KEY), "site-a", TRUSTED)


@pytest.mark.parametrize(
    ("attachment", "kind"),
    [
        (None, "unsigned"),
        (b"", "unsigned"),
        (b"Bearer token", "unsigned"),
        (sign_envelope(ENVELOPE, "site-b", KEY), "other_site"),
        (sign_envelope(ENVELOPE, "site-a", OTHER), "unknown_key"),
        (sign_envelope(ENVELOPE + b"x", "site-a", KEY), "bad_signature"),
        # a signature for site-b made to look like one for site-a
        (sign_envelope(ENVELOPE, "site-b", KEY)[:-6] + b"site-a", "bad_signature"),
    ],
    ids=["none", "empty", "bearer", "other_site", "unknown_key", "bad_signature", "site_renamed"],
)
def test_forgeries_are_refused(attachment: bytes | None, kind: str) -> None:
    with pytest.raises(CommandAuthError) as caught:
        verify_envelope(ENVELOPE, attachment, "site-a", TRUSTED)
    assert caught.value.kind == kind
