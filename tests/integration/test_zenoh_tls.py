"""Mutual TLS on the Zenoh WAN link (issue 9), with certificates made by fleetlink.common.certs.

The shipped templates are used as they are: the cloud router accepts TLS only and requires a
client certificate from the fleet CA; the edge router connects with its site certificate and
checks the cloud's. Refusals are asserted as zenoh shows them: a client-mode session fails to
open (zenoh.ZError), a router-mode edge opens but has no link to the cloud.

The log check runs a whole exchange (including a refused client) in a subprocess with zenoh's
debug logging on (RUST_LOG=debug) and Python logging at DEBUG, and looks for private-key
material in everything it wrote.
"""

from __future__ import annotations

import base64
import logging
import os
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import pytest
import zenoh

from fleetlink.common.certs import CLOUD_NAME, CertBundle, edge_name
from tests.helpers import wait_until
from tests.integration.zenoh_topology import (
    Cloud,
    Collector,
    client_config,
    edge_identity_config,
    make_bundle,
    opened,
    routers_connected,
    tls_cloud,
    tls_edge,
    uplink_config,
)

REPO = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def bundle(tmp_path_factory: pytest.TempPathFactory) -> CertBundle:
    return make_bundle(tmp_path_factory.mktemp("fleet-ca"))


@pytest.fixture(scope="module")
def foreign(tmp_path_factory: pytest.TempPathFactory) -> CertBundle:
    """Certificates with the same names, from another CA."""
    return make_bundle(tmp_path_factory.mktemp("other-ca"))


@pytest.fixture(scope="module")
def cloud(bundle: CertBundle) -> Iterator[Cloud]:
    with tls_cloud(bundle) as cloud:
        yield cloud


def _links_from(session: zenoh.Session, zid: zenoh.ZenohId) -> list[zenoh.Link]:
    return [link for link in session.info.links() if str(link.zid) == str(zid)]


def _ack(query: zenoh.Query) -> None:
    batch = query.payload.to_bytes() if query.payload is not None else b""
    query.reply(query.key_expr, b"acked:" + batch)


def test_edge_and_cloud_exchange_data_over_mutual_tls(bundle: CertBundle, cloud: Cloud) -> None:
    with (
        tls_edge(bundle, "site-a", cloud.endpoint) as edge,
        opened(uplink_config(bundle, cloud.endpoint)) as uplink,
        opened(client_config(edge.endpoint)) as agent,
    ):
        # The WAN link is TLS and each side saw the other's certificate name.
        [edge_to_cloud] = _links_from(edge.session, cloud.session.info.zid())
        assert edge_to_cloud.dst.startswith("tls/")
        assert edge_to_cloud.auth_identifier == CLOUD_NAME
        [cloud_to_edge] = _links_from(cloud.session, edge.session.info.zid())
        assert cloud_to_edge.auth_identifier == edge_name("site-a")

        at_cloud, at_site = Collector(), Collector()
        keep = [
            uplink.declare_subscriber("fleetlink/site-a/events/**", at_cloud),
            agent.declare_subscriber("fleetlink/site-a/commands/**", at_site),
            uplink.declare_queryable("fleetlink/*/ingest/*", _ack),
        ]
        # site -> cloud
        wait_until(
            lambda: (agent.put("fleetlink/site-a/events/robot1", b"up"), at_cloud.items)[1],
            10,
            message="event reaches the cloud over TLS",
        )
        # cloud -> site
        wait_until(
            lambda: (uplink.put("fleetlink/site-a/commands/robot1", b"down"), at_site.items)[1],
            10,
            message="command reaches the site over TLS",
        )
        # an ingest batch as a query, acknowledged by the uplink's reply
        replies = [r.ok for r in agent.get("fleetlink/site-a/ingest/edge-1", payload=b"batch-7", timeout=5)]
        assert [(str(r.key_expr), r.payload.to_bytes()) for r in replies if r is not None] == [
            ("fleetlink/site-a/ingest/edge-1", b"acked:batch-7")
        ]
        assert at_cloud.items[0] == ("fleetlink/site-a/events/robot1", b"up")
        assert at_site.items[0] == ("fleetlink/site-a/commands/robot1", b"down")
        del keep


@pytest.mark.parametrize(
    "who",
    [
        "no client certificate",
        "certificate from another CA",
        "plain TCP to the TLS port",
        "certificate from another CA, trusting it",
    ],
)
def test_clients_without_a_valid_certificate_are_refused(
    who: str, bundle: CertBundle, foreign: CertBundle, cloud: Cloud
) -> None:
    tcp_endpoint = cloud.endpoint.replace("tls/", "tcp/")
    conf = {
        "no client certificate": lambda: client_config(cloud.endpoint, bundle=bundle),
        # Signed by another CA, but presented to a cloud that trusts our CA only.
        "certificate from another CA": lambda: _mixed(bundle, foreign, cloud.endpoint),
        "plain TCP to the TLS port": lambda: client_config(tcp_endpoint),
        # The foreign client also distrusts the cloud's server certificate.
        "certificate from another CA, trusting it": lambda: edge_identity_config(
            foreign, "site-a", cloud.endpoint
        ),
    }[who]()
    before = len(cloud.session.info.transports())
    with pytest.raises(zenoh.ZError, match="Unable to connect"):
        zenoh.open(conf)
    assert len(cloud.session.info.transports()) == before


def _mixed(trust: CertBundle, identity_from: CertBundle, endpoint: str) -> zenoh.Config:
    """Trusts our CA (so it accepts the cloud) but presents a certificate from another CA."""
    conf = edge_identity_config(identity_from, "site-a", endpoint)
    conf.insert_json5("transport/link/tls/root_ca_certificate", f'"{trust.ca_certificate}"')
    return conf


def test_edge_router_with_a_foreign_certificate_gets_no_link(
    bundle: CertBundle, foreign: CertBundle, cloud: Cloud
) -> None:
    # A router-mode edge keeps retrying in the background instead of failing to open, so the
    # refusal shows as: no link on either side, and nothing it carries reaches the cloud, while
    # a properly certified edge next to it connects and delivers.
    with (
        tls_edge(foreign, "site-b", cloud.endpoint) as bad_edge,
        tls_edge(bundle, "site-a", cloud.endpoint) as good_edge,
        opened(uplink_config(bundle, cloud.endpoint)) as uplink,
        opened(client_config(bad_edge.endpoint)) as bad_agent,
        opened(client_config(good_edge.endpoint)) as good_agent,
    ):
        at_cloud = Collector()
        keep = uplink.declare_subscriber("fleetlink/**", at_cloud)

        def good_data_flowing() -> bool:
            bad_agent.put("fleetlink/site-b/events/x", b"bad")
            good_agent.put("fleetlink/site-a/events/x", b"good")
            return at_cloud.count("fleetlink/site-a/") >= 20

        wait_until(good_data_flowing, 10, message="certified edge delivers")
        assert at_cloud.count("fleetlink/site-b/") == 0
        assert routers_connected(bad_edge.session) == 0
        assert _links_from(cloud.session, bad_edge.session.info.zid()) == []
        assert routers_connected(good_edge.session) == 1
        del keep


def test_edge_refuses_an_impostor_cloud(bundle: CertBundle, foreign: CertBundle) -> None:
    # A cloud router with a server certificate from another CA: the edge does not connect.
    with tls_cloud(foreign) as impostor, tls_edge(bundle, "site-a", impostor.endpoint) as edge:
        assert routers_connected(edge.session) == 0
        assert impostor.session.info.transports() == []


# --- no secrets in logs ----------------------------------------------------------------------


def _key_material(directory: Path) -> list[str]:
    """Strings that would betray a private key: each key's base64 body lines and DER bytes."""
    needles = ["PRIVATE KEY"]
    for key_file in sorted(directory.glob("*-key.pem")):
        lines = [ln for ln in key_file.read_text().splitlines() if ln and not ln.startswith("-----")]
        needles += lines
        der = base64.b64decode("".join(lines))
        needles += [der.hex(), der[-32:].hex(), repr(der[-32:])[2:-1]]
    return needles


def test_no_private_key_material_in_logs(tmp_path: Path) -> None:
    env = dict(os.environ, RUST_LOG="debug", PYTHONPATH=str(REPO), NO_COLOR="1")
    proc = subprocess.run(
        [sys.executable, "-m", "tests.integration.test_zenoh_tls", str(tmp_path / "certs")],
        cwd=REPO,
        env=env,
        capture_output=True,
        text=True,
        timeout=60,
        check=False,
    )
    output = proc.stdout + proc.stderr
    assert proc.returncode == 0, output[-3000:]
    assert "exchange ok; refused ok" in proc.stdout
    # The logs were really on and cover the TLS links and the certificates' paths.
    assert "tls/127.0.0.1" in output
    assert "fleetlink.common.certs" in output
    needles = _key_material(tmp_path / "certs")
    assert len(needles) > 10
    leaked = [needle for needle in needles if needle in output]
    assert leaked == []


def test_no_private_key_material_in_python_logs(tmp_path: Path, caplog: pytest.LogCaptureFixture) -> None:
    caplog.set_level(logging.DEBUG)
    bundle = make_bundle(tmp_path)
    with tls_cloud(bundle) as cloud, tls_edge(bundle, "site-a", cloud.endpoint) as edge:
        assert routers_connected(edge.session) == 1
    assert "wrote certificate" in caplog.text
    assert [n for n in _key_material(tmp_path) if n in caplog.text] == []


def _log_probe(cert_dir: Path) -> int:
    """Run in a subprocess by test_no_private_key_material_in_logs, with every log on."""
    logging.basicConfig(level=logging.DEBUG, stream=sys.stderr)
    zenoh.init_log_from_env_or("debug")
    bundle = make_bundle(cert_dir)
    with (
        tls_cloud(bundle) as cloud,
        tls_edge(bundle, "site-a", cloud.endpoint) as edge,
        opened(uplink_config(bundle, cloud.endpoint)) as uplink,
        opened(client_config(edge.endpoint)) as agent,
    ):
        got = Collector()
        keep = uplink.declare_subscriber("fleetlink/**", got)
        wait_until(lambda: (agent.put("fleetlink/site-a/events/x", b"x"), got.items)[1], 10)
        try:
            zenoh.open(client_config(cloud.endpoint, bundle=bundle))  # no client certificate
        except zenoh.ZError:
            refused = True
        else:
            refused = False
        del keep
    print(f"exchange ok; refused {'ok' if refused else 'NOT'}", flush=True)
    return 0 if refused else 1


if __name__ == "__main__":
    sys.exit(_log_probe(Path(sys.argv[1])))
