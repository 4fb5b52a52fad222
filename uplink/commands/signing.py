"""The uplink's half of command authentication: every envelope it sends is signed for the site it
addresses (``fleetlink.wire.command_auth``), with the key of ``command_signing.key_file``."""

from __future__ import annotations

from cryptography.hazmat.primitives.asymmetric.ed25519 import Ed25519PrivateKey

from fleetlink.common.command_keys import load_signing_key
from fleetlink.common.errors import ConfigError
from fleetlink.uplink.config import UplinkConfig
from fleetlink.wire.command_auth import ANY_SITE, sign_envelope


class CommandSigner:
    """Signs the envelopes the uplink sends with its Ed25519 key, each for the site it addresses."""

    def __init__(self, key: Ed25519PrivateKey) -> None:
        self._key = key

    def attachment(self, envelope: bytes, site: str | None) -> bytes:
        """The signature for ``envelope`` sent to ``site`` (None: every site)."""
        return sign_envelope(envelope, site or ANY_SITE, self._key)


def load_signer(config: UplinkConfig) -> CommandSigner:
    """The signer of ``command_signing.key_file`` (a ``ConfigError`` naming it when unusable)."""
    section = config.command_signing
    if section is None:
        raise ConfigError("command_signing.key_file: required with command mappings")
    try:
        return CommandSigner(load_signing_key(section.key_file))
    except ConfigError:
        raise
    except Exception as exc:  # noqa: BLE001 - CertError and friends: name the setting
        raise ConfigError(f"command_signing.key_file: {exc}") from None
