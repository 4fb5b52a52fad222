"""The key pair commands are signed with: an Ed25519 private key for the uplink, its public key
for every repeater (``fleetlink certs command-key DIR``; ``fleetlink.wire.command_auth``).

Files: ``command-signing-key.pem`` (PKCS#8, written 0600, never logged) and
``command-signing.pem`` (the public key, SubjectPublicKeyInfo). Errors name the file.
"""

from __future__ import annotations

from pathlib import Path

from cryptography.hazmat.primitives import serialization
from cryptography.hazmat.primitives.asymmetric.ed25519 import Ed25519PrivateKey, Ed25519PublicKey

from fleetlink.common.certs import CertError, make_dir, write_private, write_public

PRIVATE_FILE = "command-signing-key.pem"
PUBLIC_FILE = "command-signing.pem"


def write_command_key(directory: Path, key: Ed25519PrivateKey | None = None) -> tuple[Path, Path]:
    """Write a (new) signing key and its public key into ``directory``; returns their paths."""
    key = key or Ed25519PrivateKey.generate()
    make_dir(directory)
    private, public = directory / PRIVATE_FILE, directory / PUBLIC_FILE
    write_private(
        private,
        key.private_bytes(
            serialization.Encoding.PEM, serialization.PrivateFormat.PKCS8, serialization.NoEncryption()
        ),
    )
    write_public(
        public,
        key.public_key().public_bytes(
            serialization.Encoding.PEM, serialization.PublicFormat.SubjectPublicKeyInfo
        ),
    )
    return private, public


def _read(path: Path, what: str) -> bytes:
    try:
        return path.read_bytes()
    except OSError as exc:
        raise CertError(f"{path}: cannot read the {what}: {exc.strerror}") from None


def load_signing_key(path: Path) -> Ed25519PrivateKey:
    """Read the uplink's Ed25519 signing key from an unencrypted PEM file.

    Raises ``CertError`` naming the file when it cannot be read or holds another kind of key.
    """
    try:
        key = serialization.load_pem_private_key(_read(path, "command signing key"), password=None)
    except ValueError:
        raise CertError(f"{path}: not an unencrypted PEM private key") from None
    if not isinstance(key, Ed25519PrivateKey):
        raise CertError(f"{path}: expected an Ed25519 key, got {type(key).__name__}")
    return key


def load_public_key(path: Path) -> Ed25519PublicKey:
    """Read the Ed25519 public key repeaters verify commands with from a PEM file.

    Raises ``CertError`` naming the file when it cannot be read or holds another kind of key.
    """
    try:
        key = serialization.load_pem_public_key(_read(path, "command public key"))
    except ValueError:
        raise CertError(f"{path}: not a PEM public key") from None
    if not isinstance(key, Ed25519PublicKey):
        raise CertError(f"{path}: expected an Ed25519 public key, got {type(key).__name__}")
    return key
