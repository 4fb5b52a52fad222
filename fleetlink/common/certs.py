"""Certificates for the Zenoh WAN link: a private CA, router (server) and client certificates.

The edge router connects to the cloud router over TLS with mutual authentication; the cloud
identifies each edge by the common name of its client certificate (``edge-<site>``) and the
edge identifies the cloud by the server certificate's common name (``fleetlink-cloud``). The
Zenoh ACLs in ``deploy/zenoh/`` are keyed on those names. An edge certificate also names its
site in a URI subject alternative name, ``urn:fleetlink:site:<site>``: :func:`certificate_site`
reads it back and refuses a certificate whose common name and site disagree, and rendering an
edge router's config checks that its certificate is the site's (docs/security.md).

This module makes such a set with the ``cryptography`` package: ECDSA P-256 keys, PKCS#8 PEM
private keys, X.509 v3 certificates with the key-usage extensions rustls (zenoh's TLS stack)
checks. Pure part: :func:`new_ca`, :func:`issue` (they take ``now``); disk part:
:func:`write_identity`, :func:`write_ca`, :func:`generate_bundle`.

Private keys are written with mode 0600 and never appear in ``repr`` or log lines.
"""

from __future__ import annotations

import ipaddress
import logging
import os
from collections.abc import Sequence
from dataclasses import dataclass, field
from datetime import datetime, timedelta
from pathlib import Path

from cryptography import x509
from cryptography.hazmat.primitives import hashes, serialization
from cryptography.hazmat.primitives.asymmetric import ec
from cryptography.x509.oid import ExtendedKeyUsageOID, NameOID

from fleetlink.common.errors import FleetlinkError
from fleetlink.common.names import cert_name_problem

__all__ = [
    "CLOUD_NAME",
    "UPLINK_NAME",
    "CertBundle",
    "CertError",
    "CertificateAuthority",
    "Identity",
    "IdentityFiles",
    "certificate_site",
    "check_site_certificate",
    "edge_name",
    "generate_bundle",
    "issue",
    "load_ca",
    "new_ca",
    "write_ca",
    "write_identity",
]

log = logging.getLogger(__name__)

#: Common name of the cloud router's server certificate (the edge ACL's WAN subject).
CLOUD_NAME = "fleetlink-cloud"
#: Common name of the uplink's client certificate (full rights on ``fleetlink/**`` at the cloud).
UPLINK_NAME = "fleetlink-uplink"

_DEFAULT_HOSTS = ("localhost", "127.0.0.1")


class CertError(FleetlinkError):
    """A certificate could not be made, read or written; the message names the file or name."""


EDGE_PREFIX = "edge-"
SITE_URI_PREFIX = "urn:fleetlink:site:"


def edge_name(site: str) -> str:
    """Common name of a site's edge router certificate (the cloud ACL subject for that site)."""
    return f"{EDGE_PREFIX}{site}"


def site_uri(site: str) -> str:
    """The subject alternative name that binds a certificate to a site."""
    return f"{SITE_URI_PREFIX}{site}"


def certificate_site(cert: x509.Certificate) -> str | None:
    """The site a certificate is bound to (None: a certificate of no site, e.g. the cloud's).

    Raises ``CertError`` when it names a site that its common name is not ``edge-<site>`` for,
    or is named like an edge certificate without naming its site.
    """
    try:
        names = cert.extensions.get_extension_for_class(x509.SubjectAlternativeName).value
        uris = [
            u
            for u in names.get_values_for_type(x509.UniformResourceIdentifier)
            if u.startswith(SITE_URI_PREFIX)
        ]
    except x509.ExtensionNotFound:
        uris = []
    common = _common_name(cert)
    if len(uris) > 1:
        raise CertError(f"certificate {common!r} names {len(uris)} sites")
    if not uris:
        if common.startswith(EDGE_PREFIX):
            raise CertError(
                f"certificate {common!r} does not name its site ({SITE_URI_PREFIX}...); reissue it "
                "with 'fleetlink certs issue DIR --site SITE'"
            )
        return None
    site = uris[0][len(SITE_URI_PREFIX) :]
    if common != edge_name(site):
        raise CertError(
            f"certificate {common!r} names site {site!r}, so it must be named {edge_name(site)!r}"
        )
    return site


@dataclass(frozen=True)
class CertificateAuthority:
    """A CA certificate and its private key (kept out of ``repr``)."""

    certificate: x509.Certificate
    key: ec.EllipticCurvePrivateKey = field(repr=False)

    @property
    def common_name(self) -> str:
        """The CA certificate's subject common name (empty when it has none)."""
        return _common_name(self.certificate)


@dataclass(frozen=True)
class Identity:
    """An issued certificate and its private key (kept out of ``repr``)."""

    certificate: x509.Certificate
    key: ec.EllipticCurvePrivateKey = field(repr=False)

    @property
    def common_name(self) -> str:
        """The certificate's subject common name, e.g. ``edge-<site>`` (empty when it has none)."""
        return _common_name(self.certificate)


@dataclass(frozen=True)
class IdentityFiles:
    """Where an identity was written: ``<name>.pem`` and ``<name>-key.pem``."""

    name: str
    certificate: Path
    key: Path


@dataclass(frozen=True)
class CertBundle:
    """A directory holding ``ca.pem`` and the identities issued by that CA."""

    directory: Path
    ca_certificate: Path
    identities: dict[str, IdentityFiles]

    def __getitem__(self, name: str) -> IdentityFiles:
        try:
            return self.identities[name]
        except KeyError:
            raise CertError(f"no certificate named {name!r} in {self.directory}") from None


def _check_name(name: str) -> None:
    problem = cert_name_problem(name)
    if problem is not None:
        raise CertError(f"certificate name {name!r}: {problem}")


def _common_name(cert: x509.Certificate) -> str:
    attrs = cert.subject.get_attributes_for_oid(NameOID.COMMON_NAME)
    if not attrs:
        return ""
    value = attrs[0].value
    return value if isinstance(value, str) else value.decode()


def _subject(common_name: str, organization: str) -> x509.Name:
    return x509.Name(
        [
            x509.NameAttribute(NameOID.ORGANIZATION_NAME, organization),
            x509.NameAttribute(NameOID.COMMON_NAME, common_name),
        ]
    )


def new_ca(
    common_name: str = "fleetlink CA",
    *,
    now: datetime,
    valid_days: int = 3650,
    organization: str = "fleetlink",
) -> CertificateAuthority:
    """A self-signed CA that may sign end-entity certificates only (path length 0)."""
    if valid_days <= 0:
        raise CertError(f"CA {common_name!r}: valid_days must be positive, got {valid_days}")
    key = ec.generate_private_key(ec.SECP256R1())
    name = _subject(common_name, organization)
    cert = (
        x509.CertificateBuilder()
        .subject_name(name)
        .issuer_name(name)
        .public_key(key.public_key())
        .serial_number(x509.random_serial_number())
        .not_valid_before(now - timedelta(minutes=5))
        .not_valid_after(now + timedelta(days=valid_days))
        .add_extension(x509.BasicConstraints(ca=True, path_length=0), critical=True)
        .add_extension(
            x509.KeyUsage(
                digital_signature=True,
                content_commitment=False,
                key_encipherment=False,
                data_encipherment=False,
                key_agreement=False,
                key_cert_sign=True,
                crl_sign=True,
                encipher_only=False,
                decipher_only=False,
            ),
            critical=True,
        )
        .add_extension(x509.SubjectKeyIdentifier.from_public_key(key.public_key()), critical=False)
        .sign(key, hashes.SHA256())
    )
    return CertificateAuthority(cert, key)


def _alt_names(hosts: Sequence[str]) -> list[x509.GeneralName]:
    names: list[x509.GeneralName] = []
    for host in hosts:
        try:
            names.append(x509.IPAddress(ipaddress.ip_address(host)))
        except ValueError:
            names.append(x509.DNSName(host))
    return names


def issue(
    ca: CertificateAuthority,
    common_name: str,
    *,
    now: datetime,
    server: bool = False,
    client: bool = False,
    hosts: Sequence[str] = (),
    valid_days: int = 825,
    organization: str = "fleetlink",
    site: str | None = None,
) -> Identity:
    """Issue an end-entity certificate signed by ``ca``.

    ``site``: an edge certificate, bound to that site (its common name must be ``edge-<site>``;
    an ``edge-`` name without a site is refused).

    ``server`` adds the TLS server usage (a listening router; ``hosts`` become DNS/IP subject
    alternative names, which clients verify when ``verify_name_on_connect`` is on); ``client``
    adds TLS client usage (a connecting router or client under mTLS). A certificate may be both.
    """
    _check_name(common_name)
    if site is not None and common_name != edge_name(site):
        raise CertError(
            f"certificate {common_name!r}: a certificate of site {site!r} is named {edge_name(site)!r}"
        )
    if site is None and common_name.startswith(EDGE_PREFIX):
        raise CertError(f"certificate {common_name!r}: edge certificates are issued for a site (--site)")
    if not (server or client):
        raise CertError(f"certificate {common_name!r}: choose server, client or both")
    if server and not hosts:
        raise CertError(f"server certificate {common_name!r}: give at least one host name or IP")
    if valid_days <= 0:
        raise CertError(f"certificate {common_name!r}: valid_days must be positive, got {valid_days}")
    key = ec.generate_private_key(ec.SECP256R1())
    usages = [ExtendedKeyUsageOID.SERVER_AUTH] if server else []
    if client:
        usages.append(ExtendedKeyUsageOID.CLIENT_AUTH)
    builder = (
        x509.CertificateBuilder()
        .subject_name(_subject(common_name, organization))
        .issuer_name(ca.certificate.subject)
        .public_key(key.public_key())
        .serial_number(x509.random_serial_number())
        .not_valid_before(now - timedelta(minutes=5))
        .not_valid_after(now + timedelta(days=valid_days))
        .add_extension(x509.BasicConstraints(ca=False, path_length=None), critical=True)
        .add_extension(
            x509.KeyUsage(
                digital_signature=True,
                content_commitment=False,
                key_encipherment=False,
                data_encipherment=False,
                key_agreement=False,
                key_cert_sign=False,
                crl_sign=False,
                encipher_only=False,
                decipher_only=False,
            ),
            critical=True,
        )
        .add_extension(x509.ExtendedKeyUsage(usages), critical=False)
        .add_extension(x509.SubjectKeyIdentifier.from_public_key(key.public_key()), critical=False)
        .add_extension(
            x509.AuthorityKeyIdentifier.from_issuer_public_key(ca.key.public_key()), critical=False
        )
    )
    alt = _alt_names(hosts)
    if site is not None:
        alt.append(x509.UniformResourceIdentifier(site_uri(site)))
    if alt:
        builder = builder.add_extension(x509.SubjectAlternativeName(alt), critical=False)
    return Identity(builder.sign(ca.key, hashes.SHA256()), key)


# --- disk ------------------------------------------------------------------------------------


def _key_pem(key: ec.EllipticCurvePrivateKey) -> bytes:
    return key.private_bytes(
        serialization.Encoding.PEM,
        serialization.PrivateFormat.PKCS8,
        serialization.NoEncryption(),
    )


def write_private(path: Path, data: bytes) -> None:
    """Write a private key readable by its owner only (created 0600, never world-readable)."""
    try:
        fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
        with os.fdopen(fd, "wb") as fh:
            fh.write(data)
        os.chmod(path, 0o600)
    except OSError as exc:
        raise CertError(f"cannot write private key {path}: {exc.strerror}") from None


def write_public(path: Path, data: bytes) -> None:
    try:
        path.write_bytes(data)
    except OSError as exc:
        raise CertError(f"cannot write certificate {path}: {exc.strerror}") from None


def make_dir(directory: Path) -> None:
    try:
        directory.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise CertError(f"cannot create certificate directory {directory}: {exc.strerror}") from None


def write_ca(ca: CertificateAuthority, directory: Path) -> tuple[Path, Path]:
    """Write ``ca.pem`` and ``ca-key.pem``; returns their paths."""
    make_dir(directory)
    cert_path, key_path = directory / "ca.pem", directory / "ca-key.pem"
    write_public(cert_path, ca.certificate.public_bytes(serialization.Encoding.PEM))
    write_private(key_path, _key_pem(ca.key))
    log.debug("wrote CA certificate path=%s cn=%s", cert_path, ca.common_name)
    return cert_path, key_path


def write_identity(identity: Identity, directory: Path, name: str | None = None) -> IdentityFiles:
    """Write ``<name>.pem`` and ``<name>-key.pem`` (name defaults to the common name)."""
    name = name or identity.common_name
    _check_name(name)
    make_dir(directory)
    cert_path, key_path = directory / f"{name}.pem", directory / f"{name}-key.pem"
    write_public(cert_path, identity.certificate.public_bytes(serialization.Encoding.PEM))
    write_private(key_path, _key_pem(identity.key))
    log.debug("wrote certificate path=%s cn=%s", cert_path, identity.common_name)
    return IdentityFiles(name, cert_path, key_path)


def check_site_certificate(path: Path, site: str) -> None:
    """Raise ``CertError`` unless ``path`` holds a certificate bound to ``site``."""
    try:
        cert = x509.load_pem_x509_certificate(path.read_bytes())
    except OSError as exc:
        raise CertError(f"{path}: cannot read the site certificate: {exc.strerror}") from None
    except ValueError:
        raise CertError(f"{path}: not a PEM certificate") from None
    bound = certificate_site(cert)
    if bound != site:
        raise CertError(f"{path}: the certificate is site {bound!r}'s, not site {site!r}'s")


def load_ca(directory: Path) -> CertificateAuthority:
    """Read ``ca.pem`` and ``ca-key.pem`` back (to issue more certificates later)."""
    cert_path, key_path = directory / "ca.pem", directory / "ca-key.pem"
    try:
        cert = x509.load_pem_x509_certificate(cert_path.read_bytes())
        key = serialization.load_pem_private_key(key_path.read_bytes(), password=None)
    except OSError as exc:
        raise CertError(f"cannot read CA from {directory}: {exc.strerror}: {exc.filename}") from None
    except ValueError:
        raise CertError(f"{cert_path} / {key_path}: not a PEM certificate and unencrypted key") from None
    if not isinstance(key, ec.EllipticCurvePrivateKey):
        raise CertError(f"{key_path}: expected an EC private key, got {type(key).__name__}")
    return CertificateAuthority(cert, key)


def generate_bundle(
    directory: Path,
    *,
    now: datetime,
    sites: Sequence[str] = (),
    servers: Sequence[str] = (CLOUD_NAME,),
    clients: Sequence[str] = (UPLINK_NAME,),
    hosts: Sequence[str] = _DEFAULT_HOSTS,
    ca_name: str = "fleetlink CA",
) -> CertBundle:
    """A fresh CA in ``directory`` plus server certificates (for ``hosts``) and client ones.

    Each site gets a client certificate named ``edge-<site>``. Existing files are replaced.
    """
    ca = new_ca(ca_name, now=now)
    ca_cert, _ = write_ca(ca, directory)
    identities: dict[str, IdentityFiles] = {}
    for name in servers:
        identities[name] = write_identity(issue(ca, name, now=now, server=True, hosts=hosts), directory)
    for name, site in [*((c, None) for c in clients), *((edge_name(s), s) for s in sites)]:
        if name in identities:
            raise CertError(f"certificate name {name!r} requested twice")
        identities[name] = write_identity(issue(ca, name, now=now, client=True, site=site), directory)
    return CertBundle(directory, ca_cert, identities)
