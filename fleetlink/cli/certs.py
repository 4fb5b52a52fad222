"""``fleetlink certs``: make the CA and certificates for the Zenoh WAN link (mutual TLS).

``init`` creates a CA with the cloud router's server certificate, the uplink's client
certificate and one ``edge-<site>`` client certificate per site; ``issue`` adds certificates
from an existing CA (a new site, a second cloud host); ``show`` lists what a directory holds.
Private keys are written 0600 and never printed.
"""

from __future__ import annotations

import argparse
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

from cryptography import x509
from cryptography.x509.oid import ExtendedKeyUsageOID

from fleetlink.common.certs import (
    CLOUD_NAME,
    CertError,
    certificate_site,
    edge_name,
    generate_bundle,
    issue,
    load_ca,
    write_identity,
)
from fleetlink.common.command_keys import write_command_key


def register(sub: Any) -> None:
    """Add ``fleetlink certs`` (``init``, ``issue``, ``show``, ``command-key``) to the subcommands."""
    parser: argparse.ArgumentParser = sub.add_parser(
        "certs",
        help="make the CA and certificates for TLS between edge and cloud Zenoh routers",
        description="Certificates for the Zenoh WAN link: the cloud router proves it is "
        f"'{CLOUD_NAME}', each edge router proves it is 'edge-<site>' (the names the router "
        "ACLs in deploy/zenoh/ are keyed on).",
    )
    actions = parser.add_subparsers(dest="action", metavar="ACTION", required=True)

    init = actions.add_parser("init", help="new CA + cloud, uplink and per-site edge certificates")
    init.add_argument("dir", type=Path, help="output directory")
    init.add_argument(
        "--site",
        action="append",
        default=[],
        metavar="SITE",
        help="a site to issue edge-SITE for (repeatable)",
    )
    init.add_argument(
        "--host",
        action="append",
        default=[],
        metavar="HOST",
        help="DNS name or IP the edges use to reach the cloud router (repeatable; "
        "default: localhost and 127.0.0.1)",
    )
    init.add_argument("--force", action="store_true", help="replace an existing CA in DIR")
    init.set_defaults(handler=_init)

    add = actions.add_parser("issue", help="issue one more certificate from the CA in DIR")
    add.add_argument("dir", type=Path, help="directory holding ca.pem and ca-key.pem")
    who = add.add_mutually_exclusive_group(required=True)
    who.add_argument("--site", metavar="SITE", help="an edge router client certificate: edge-SITE")
    who.add_argument("--name", metavar="NAME", help="any common name (with --server and/or --client)")
    add.add_argument("--server", action="store_true", help="TLS server usage (needs --host)")
    add.add_argument("--client", action="store_true", help="TLS client usage")
    add.add_argument("--host", action="append", default=[], metavar="HOST", help="server name or IP")
    add.add_argument("--days", type=int, default=825, help="validity in days (default: %(default)s)")
    add.set_defaults(handler=_issue)

    key = actions.add_parser(
        "command-key",
        help="a new key pair commands are signed with (the uplink's private key, the repeaters' public key)",
    )
    key.add_argument("dir", type=Path, help="output directory")
    key.add_argument("--force", action="store_true", help="replace an existing key in DIR")
    key.set_defaults(handler=_command_key)

    show = actions.add_parser("show", help="list the certificates in DIR")
    show.add_argument("dir", type=Path)
    show.set_defaults(handler=_show)


def _init(args: argparse.Namespace) -> int:
    if (args.dir / "ca.pem").exists() and not args.force:
        raise CertError(f"{args.dir / 'ca.pem'} exists; use `issue` to add certificates, or --force")
    hosts = tuple(args.host) or ("localhost", "127.0.0.1")
    bundle = generate_bundle(args.dir, now=datetime.now(UTC), sites=args.site, hosts=hosts)
    print(f"{'CA':<18} {bundle.ca_certificate}")
    for name, files in bundle.identities.items():
        print(f"{name:<18} {files.certificate}  (key {files.key.name}, mode 0600)")
    print(f"cloud router hosts: {', '.join(hosts)}")
    private, public = write_command_key(args.dir)
    print(f"{'command signing':<18} {private} (uplink, mode 0600); {public.name} (repeaters)")
    return 0


def _command_key(args: argparse.Namespace) -> int:
    private = args.dir / "command-signing-key.pem"
    if private.exists() and not args.force:
        raise CertError(
            f"{private} exists; use --force to replace it (repeaters then need the new public key)"
        )
    private, public = write_command_key(args.dir)
    print(f"uplink (command_signing.key_file): {private}  (mode 0600)")
    print(f"repeaters (repeater.command_keys): {public}")
    return 0


def _issue(args: argparse.Namespace) -> int:
    name = edge_name(args.site) if args.site else args.name
    client = args.client or bool(args.site)
    ca = load_ca(args.dir)
    ident = issue(
        ca,
        name,
        now=datetime.now(UTC),
        server=args.server,
        client=client,
        hosts=args.host,
        valid_days=args.days,
        site=args.site,
    )
    files = write_identity(ident, args.dir)
    print(f"{name}  {files.certificate}  (key {files.key.name}, mode 0600)")
    return 0


def _usages(cert: x509.Certificate) -> str:
    try:
        eku = cert.extensions.get_extension_for_class(x509.ExtendedKeyUsage).value
    except x509.ExtensionNotFound:
        return "ca"
    names = {ExtendedKeyUsageOID.SERVER_AUTH: "server", ExtendedKeyUsageOID.CLIENT_AUTH: "client"}
    return "+".join(names.get(oid, oid.dotted_string) for oid in eku)


def _show(args: argparse.Namespace) -> int:
    paths = sorted(
        p
        for p in args.dir.glob("*.pem")
        if not p.name.endswith("-key.pem") and p.name != "command-signing.pem"
    )
    if not paths:
        raise CertError(f"no certificates in {args.dir}")
    for path in paths:
        try:
            cert = x509.load_pem_x509_certificate(path.read_bytes())
        except ValueError:
            print(f"{path.name:<28} (not a PEM certificate)")
            continue
        cn = cert.subject.rfc4514_string()
        expires = cert.not_valid_after_utc.date().isoformat()
        try:
            site = certificate_site(cert)
            bound = f"  site {site}" if site else ""
        except CertError as exc:
            bound = f"  ({exc})"
        print(f"{path.name:<28} {_usages(cert):<14} expires {expires}  {cn}{bound}")
    return 0


__all__ = ["register"]
