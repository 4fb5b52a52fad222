"""Signed command envelopes: a repeater applies a command only if the cloud signed it for its site.

The uplink signs every envelope it sends with an Ed25519 key (``command_signing.key_file``);
repeaters hold only the public key (``repeater.command_keys``), so nothing at a site, the
repeater's own host included, can make a command another repeater accepts. The signature
travels as the Zenoh query's attachment, beside the envelope bytes it covers::

    attachment = "FLS1" | key id (8 bytes: SHA-256 of the raw public key, first 8) | signature (64)
                 | target site (UTF-8, the rest)
    signed     = "fleetlink command v1" 00 | target site | 00 | envelope bytes

The target site is the site the uplink addressed, or ``*`` for a command sent to every site
(a robot no site holds); a repeater accepts its own site or ``*``. The envelope's command id,
lease and the repeater's journal (each id applied once) make a replayed signed envelope a
duplicate or an expired command, never a new one. Pure: bytes and keys in, bytes out.
"""

from __future__ import annotations

import hashlib
from collections.abc import Mapping

from cryptography.exceptions import InvalidSignature
from cryptography.hazmat.primitives import serialization
from cryptography.hazmat.primitives.asymmetric.ed25519 import Ed25519PrivateKey, Ed25519PublicKey

from fleetlink.wire.errors import CommandAuthError

MAGIC = b"FLS1"
ANY_SITE = "*"
_CONTEXT = b"fleetlink command v1\x00"
_KEY_ID = 8
_SIGNATURE = 64
_HEAD = len(MAGIC) + _KEY_ID + _SIGNATURE


def key_id(key: Ed25519PublicKey) -> bytes:
    """The 8 bytes naming a public key in attachments (lets repeaters hold several during a rotation)."""
    raw = key.public_bytes(serialization.Encoding.Raw, serialization.PublicFormat.Raw)
    return hashlib.sha256(raw).digest()[:_KEY_ID]


def _signed(site: str, envelope: bytes) -> bytes:
    return _CONTEXT + site.encode() + b"\x00" + envelope


def sign_envelope(envelope: bytes, site: str, key: Ed25519PrivateKey) -> bytes:
    """The attachment that makes ``envelope`` acceptable at ``site`` (or every site, ``*``)."""
    signature = key.sign(_signed(site, envelope))
    return MAGIC + key_id(key.public_key()) + signature + site.encode()


def verify_envelope(
    envelope: bytes, attachment: bytes | None, site: str, keys: Mapping[bytes, Ed25519PublicKey]
) -> None:
    """Raise ``CommandAuthError`` unless ``attachment`` signs ``envelope`` for ``site`` with one of
    ``keys`` (by key id)."""
    if not attachment or attachment[: len(MAGIC)] != MAGIC or len(attachment) <= _HEAD:
        raise CommandAuthError("unsigned", "the command carries no fleetlink signature")
    kid = attachment[len(MAGIC) : len(MAGIC) + _KEY_ID]
    signature = attachment[len(MAGIC) + _KEY_ID : _HEAD]
    try:
        target = attachment[_HEAD:].decode()
    except UnicodeDecodeError:
        raise CommandAuthError("bad_signature", "the signed target site is not text") from None
    if target not in (site, ANY_SITE):
        raise CommandAuthError("other_site", f"signed for site {target!r}, this is site {site!r}")
    key = keys.get(kid)
    if key is None:
        raise CommandAuthError(
            "unknown_key", f"signed with key {kid.hex()}, which this repeater does not trust"
        )
    try:
        key.verify(signature, _signed(target, envelope))
    except InvalidSignature:
        raise CommandAuthError("bad_signature", "the signature does not match the command") from None
