"""Test CA and certificates for the Zenoh WAN link (fleetlink.common.certs)."""

from __future__ import annotations

import stat
from datetime import UTC, datetime, timedelta
from pathlib import Path

import pytest
from cryptography import x509
from cryptography.exceptions import InvalidSignature
from cryptography.hazmat.primitives import hashes
from cryptography.x509.oid import ExtendedKeyUsageOID, NameOID

from fleetlink.cli import main
from fleetlink.common.certs import (
    CLOUD_NAME,
    UPLINK_NAME,
    CertError,
    certificate_site,
    check_site_certificate,
    edge_name,
    generate_bundle,
    issue,
    load_ca,
    new_ca,
    write_identity,
)
from fleetlink.common.command_keys import load_public_key, load_signing_key

NOW = datetime(2026, 1, 2, 3, 4, 5, tzinfo=UTC)
SERVER = ExtendedKeyUsageOID.SERVER_AUTH
CLIENT = ExtendedKeyUsageOID.CLIENT_AUTH


def usages(cert: x509.Certificate) -> list[x509.ObjectIdentifier]:
    return list(cert.extensions.get_extension_for_class(x509.ExtendedKeyUsage).value)


def test_ca_is_a_ca_for_end_entities_only() -> None:
    ca = new_ca("test CA", now=NOW, valid_days=10)
    constraints = ca.certificate.extensions.get_extension_for_class(x509.BasicConstraints).value
    assert (constraints.ca, constraints.path_length) == (True, 0)
    assert ca.common_name == "test CA"
    assert ca.certificate.not_valid_after_utc == NOW + timedelta(days=10)
    ca.certificate.verify_directly_issued_by(ca.certificate)


@pytest.mark.parametrize(
    ("server", "client", "hosts", "expected_usages", "expected_alt"),
    [
        (True, False, ["localhost", "127.0.0.1"], [SERVER], ["localhost", "127.0.0.1"]),
        (False, True, [], [CLIENT], None),
        (True, True, ["cloud.example.com"], [SERVER, CLIENT], ["cloud.example.com"]),
        (False, True, ["::1"], [CLIENT], ["::1"]),
    ],
)
def test_issue_sets_usages_and_names(
    server: bool,
    client: bool,
    hosts: list[str],
    expected_usages: list[x509.ObjectIdentifier],
    expected_alt: list[str] | None,
) -> None:
    ca = new_ca(now=NOW)
    ident = issue(ca, "node-a", now=NOW, server=server, client=client, hosts=hosts)
    ident.certificate.verify_directly_issued_by(ca.certificate)
    assert ident.common_name == "node-a"
    assert usages(ident.certificate) == expected_usages
    constraints = ident.certificate.extensions.get_extension_for_class(x509.BasicConstraints).value
    assert constraints.ca is False
    if expected_alt is None:
        with pytest.raises(x509.ExtensionNotFound):
            ident.certificate.extensions.get_extension_for_class(x509.SubjectAlternativeName)
    else:
        alt = ident.certificate.extensions.get_extension_for_class(x509.SubjectAlternativeName).value
        assert [str(name.value) for name in alt] == expected_alt


def test_certificate_from_another_ca_does_not_verify() -> None:
    ca, other = new_ca(now=NOW), new_ca(now=NOW)
    ident = issue(other, "edge-site-a", now=NOW, client=True, site="site-a")
    with pytest.raises(InvalidSignature):
        ident.certificate.verify_directly_issued_by(ca.certificate)


@pytest.mark.parametrize(
    ("name", "kwargs", "message"),
    [
        ("node-a", {}, "choose server, client or both"),
        ("cloud", {"server": True}, "at least one host"),
        ("node-a", {"client": True, "valid_days": 0}, "valid_days must be positive"),
        ("edge-a", {"client": True}, "edge certificates are issued for a site"),
        ("node-a", {"client": True, "site": "a"}, "is named 'edge-a'"),
        ("", {"client": True}, "certificate name ''"),
        ("a/b", {"client": True}, "certificate name 'a/b'"),
        ("-x", {"client": True}, "certificate name '-x'"),
    ],
)
def test_issue_errors(name: str, kwargs: dict[str, object], message: str) -> None:
    ca = new_ca(now=NOW)
    with pytest.raises(CertError, match=message):
        issue(ca, name, now=NOW, **kwargs)  # type: ignore[arg-type]


def test_private_keys_stay_out_of_repr() -> None:
    ca = new_ca(now=NOW)
    ident = issue(ca, "x", now=NOW, client=True)
    assert "key" not in repr(ident)
    assert "key" not in repr(ca)


def test_written_keys_are_owner_only_and_load_back(tmp_path: Path) -> None:
    bundle = generate_bundle(tmp_path / "certs", now=NOW, sites=["site-a", "site-b"])
    assert set(bundle.identities) == {CLOUD_NAME, UPLINK_NAME, edge_name("site-a"), edge_name("site-b")}
    for files in bundle.identities.values():
        assert stat.S_IMODE(files.key.stat().st_mode) == 0o600
        assert files.key.read_bytes().startswith(b"-----BEGIN PRIVATE KEY-----")
        cert = x509.load_pem_x509_certificate(files.certificate.read_bytes())
        assert cert.subject.get_attributes_for_oid(NameOID.COMMON_NAME)[0].value == files.name
    assert stat.S_IMODE((tmp_path / "certs" / "ca-key.pem").stat().st_mode) == 0o600
    ca = load_ca(tmp_path / "certs")
    extra = write_identity(issue(ca, "edge-site-c", now=NOW, client=True, site="site-c"), tmp_path / "certs")
    x509.load_pem_x509_certificate(extra.certificate.read_bytes()).verify_directly_issued_by(
        x509.load_pem_x509_certificate(bundle.ca_certificate.read_bytes())
    )


def test_bundle_lookup_and_load_errors(tmp_path: Path) -> None:
    bundle = generate_bundle(tmp_path, now=NOW)
    with pytest.raises(CertError, match="no certificate named 'edge-x'"):
        bundle["edge-x"]
    with pytest.raises(CertError, match="cannot read CA"):
        load_ca(tmp_path / "missing")
    with pytest.raises(CertError, match="requested twice"):
        generate_bundle(tmp_path / "dup", now=NOW, clients=[CLOUD_NAME])


# --- fleetlink certs (CLI) -------------------------------------------------------------------


def test_cli_init_issue_show(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out_dir = tmp_path / "certs"
    assert main(["certs", "init", str(out_dir), "--site", "wh-a", "--host", "cloud.example.com"]) == 0
    assert main(["certs", "issue", str(out_dir), "--site", "wh-b"]) == 0
    assert main(["certs", "issue", str(out_dir), "--name", "cloud-2", "--server", "--host", "10.0.0.2"]) == 0
    assert main(["certs", "show", str(out_dir)]) == 0
    out = capsys.readouterr().out
    for name in ("fleetlink-cloud", "fleetlink-uplink", "edge-wh-a", "edge-wh-b", "cloud-2"):
        assert (out_dir / f"{name}.pem").is_file()
        assert f"CN={name},O=fleetlink" in out
    assert "PRIVATE KEY" not in out
    assert "CN=edge-wh-b,O=fleetlink  site wh-b" in out
    assert (out_dir / "command-signing-key.pem").is_file()
    assert stat.S_IMODE((out_dir / "command-signing-key.pem").stat().st_mode) == 0o600
    cloud = x509.load_pem_x509_certificate((out_dir / "fleetlink-cloud.pem").read_bytes())
    alt = cloud.extensions.get_extension_for_class(x509.SubjectAlternativeName).value
    assert [str(n.value) for n in alt] == ["cloud.example.com"]


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["certs", "issue", "{dir}", "--name", "x", "--server"], "give at least one host"),
        (["certs", "issue", "{dir}/missing", "--site", "a"], "cannot read CA"),
        (["certs", "init", "{dir}"], "exists; use `issue`"),
        (["certs", "show", "{dir}/empty"], "no certificates"),
    ],
)
def test_cli_errors(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], argv: list[str], message: str
) -> None:
    assert main(["certs", "init", str(tmp_path)]) == 0
    (tmp_path / "empty").mkdir()
    assert main([a.replace("{dir}", str(tmp_path)) for a in argv]) == 1
    assert message in capsys.readouterr().err


# --- the site a certificate is bound to ----------------------------------------------------------


def test_an_edge_certificate_names_its_site_and_is_checked_against_it(tmp_path: Path) -> None:
    bundle = generate_bundle(tmp_path, now=NOW, sites=["site-a", "site-b"])
    cert_a = x509.load_pem_x509_certificate(bundle[edge_name("site-a")].certificate.read_bytes())
    assert certificate_site(cert_a) == "site-a"
    cloud = x509.load_pem_x509_certificate(bundle[CLOUD_NAME].certificate.read_bytes())
    assert certificate_site(cloud) is None
    check_site_certificate(bundle[edge_name("site-a")].certificate, "site-a")
    with pytest.raises(CertError, match="site 'site-b''s, not site 'site-a''s"):
        check_site_certificate(bundle[edge_name("site-b")].certificate, "site-a")
    with pytest.raises(CertError, match="cannot read"):
        check_site_certificate(tmp_path / "missing.pem", "site-a")


def test_a_certificate_whose_name_and_site_disagree_is_refused() -> None:
    ca = new_ca(now=NOW)
    plain = issue(ca, "cloud-2", now=NOW, client=True)
    assert certificate_site(plain.certificate) is None
    # a certificate made outside fleetlink: named like site A's edge, bound to site B
    forged = (
        x509.CertificateBuilder()
        .subject_name(x509.Name([x509.NameAttribute(NameOID.COMMON_NAME, "edge-site-a")]))
        .issuer_name(ca.certificate.subject)
        .public_key(plain.certificate.public_key())
        .serial_number(1)
        .not_valid_before(NOW)
        .not_valid_after(NOW + timedelta(days=1))
        .add_extension(
            x509.SubjectAlternativeName([x509.UniformResourceIdentifier("urn:fleetlink:site:site-b")]),
            critical=False,
        )
        .sign(ca.key, hashes.SHA256())
    )
    with pytest.raises(CertError, match="names site 'site-b', so it must be named 'edge-site-b'"):
        certificate_site(forged)


def test_cli_command_key(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["certs", "command-key", str(tmp_path)]) == 0
    assert "command-signing-key.pem" in capsys.readouterr().out
    signing = load_signing_key(tmp_path / "command-signing-key.pem")
    public = load_public_key(tmp_path / "command-signing.pem")
    assert public.public_bytes_raw() == signing.public_key().public_bytes_raw()
    assert main(["certs", "command-key", str(tmp_path)]) == 1
    assert "exists; use --force" in capsys.readouterr().err
    with pytest.raises(CertError, match="not an unencrypted PEM private key"):
        load_signing_key(tmp_path / "command-signing.pem")
