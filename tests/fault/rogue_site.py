"""A rogue site: a plain Zenoh client holding only site B's keys, trying what a compromised site
would. Run by tests/fault/test_security_faults.py as its own process::

    python -m tests.fault.rogue_site ATTACK --spec JSON (--cloud ENDPOINT --certs DIR | --site-router E)

With ``--cloud`` it connects straight to the cloud router with site B's edge certificate (no
site router in the way: only the cloud's ACL and the uplink stand between it and site A); with
``--site-router`` it is a client on site B's network (where the repeater and the edge are). It
speaks the wire formats with fleetlink's own encoders, so everything it sends is well formed
and only its claims are false. It prints one JSON object: what each attempt got back.
"""

from __future__ import annotations

import argparse
import io
import json
import sys
import time
import urllib.error
import urllib.request
from pathlib import Path
from typing import Any

import fastavro
import zenoh
from cryptography.hazmat.primitives.asymmetric.ed25519 import Ed25519PrivateKey

from fleetlink.common.certs import edge_name
from fleetlink.schemas.avro_schema import avro_schema
from fleetlink.schemas.single_object import fingerprint
from fleetlink.schemas.typestore import load_typestore
from fleetlink.wire import Batch, Record, decode_ack, encode_batch, single_object
from fleetlink.wire.command_auth import sign_envelope
from fleetlink.wire.commands import CommandEnvelope, encode_envelope
from fleetlink.wire.robot_events import EVENT_SCHEMA
from tests.integration.zenoh_topology import client_config
from tests.paths import IROBOT

STRING = "std_msgs/msg/String"
LIGHTRING = "irobot_create_msgs/msg/LightringLeds"
MARKER = "forged"
"""Every value the rogue writes carries this, so the test can look for it anywhere."""


class Rogue:
    def __init__(self, session: zenoh.Session, spec: dict[str, Any]) -> None:
        self.session = session
        self.spec = spec
        self.site, self.edge = spec.get("site", "site-b"), spec.get("edge", "edge-b")
        ts = load_typestore("jazzy")
        schema = avro_schema(ts, STRING, "jazzy")
        self.string_text = json.dumps(schema, separators=(",", ":"))
        self.string_fp = fingerprint(schema)
        self.parsed = fastavro.parse_schema(schema)
        self.seq = int(time.time() * 1000)

    # -- building blocks ---------------------------------------------------------------------

    def wait_matching(self, key: str, timeout: float = 15.0) -> None:
        """Until some queryable (the uplink's, the repeater's, the edge's) answers on ``key``."""
        querier = self.session.declare_querier(key)
        try:
            deadline = time.monotonic() + timeout
            # zenoh-python 1.10 returns a MatchingStatus here, though its stub says bool
            while not bool(getattr(querier.matching_status, "matching", False)):
                if time.monotonic() > deadline:
                    raise SystemExit(f"nothing answers on {key} after {timeout:.0f} s")
                time.sleep(0.05)  # ok-sleep: the poll interval of a wait with a deadline
        finally:
            querier.undeclare()

    def value(self, text: str) -> bytes:
        out = io.BytesIO()
        fastavro.schemaless_writer(out, self.parsed, {"data": text})
        return single_object(self.string_fp, out.getvalue())

    def record(self, topic: str, text: str, *, site: str | None = None, edge: str | None = None) -> Record:
        self.seq += 1
        headers = (
            ("fleetlink.site", (site or self.site).encode()),
            ("fleetlink.edge", (edge or self.edge).encode()),
            ("fleetlink.robot", b"tb4_01"),
        )
        return Record(
            topic, b"tb4_01", self.value(f"{MARKER} {text}"), headers, int(time.time() * 1000), self.seq
        )

    def send(
        self,
        records: list[Record],
        *,
        site: str | None = None,
        edge: str | None = None,
        key: str | None = None,
        schemas: dict[bytes, str] | None = None,
    ) -> dict[str, Any]:
        """One batch as an edge sends it; returns the uplink's answer (or that none came)."""
        numbered = tuple(r._replace(seq=self.seq + i) for i, r in enumerate(records, 1))
        self.seq += len(records) + 1
        batch = Batch(
            site or self.site,
            edge or self.edge,
            "durable",
            numbered[0].seq,
            numbered,
            {self.string_fp: self.string_text} if schemas is None else schemas,
        )
        where = key or f"fleetlink/{self.site}/ingest/{self.edge}"
        return self.query(where, encode_batch(batch, codec="zlib"))

    def query(self, key: str, payload: bytes, attachment: bytes | None = None) -> dict[str, Any]:
        answers: list[dict[str, Any]] = []
        for reply in self.session.get(key, payload=payload, attachment=attachment, timeout=5.0):
            if reply.ok is not None:
                data = reply.ok.payload.to_bytes()
                try:
                    ack = decode_ack(data)
                    answers.append(
                        {
                            "status": ack.status,
                            "dead_lettered": sum(f.dead_lettered for f in ack.failures),
                            "failures": [f.reason for f in ack.failures],
                        }
                    )
                except Exception:  # noqa: BLE001 - not an ack: a command reply or an admin answer
                    answers.append({"ok": data.decode("utf-8", "replace")})
            elif reply.err is not None:
                answers.append({"error": reply.err.payload.to_bytes().decode("utf-8", "replace")})
        return {"key": key, "answers": answers}

    # -- the attacks -------------------------------------------------------------------------

    def forged_site(self) -> dict[str, Any]:
        """Claim to be site A on site B's key; forge sender headers; try site A's own key."""
        a_topic = self.spec["a_topic"]
        return {
            "claims_site_a": self.send(
                [self.record(a_topic, "claims site-a", site="site-a", edge="edge-a")],
                site="site-a",
                edge="edge-a",
            ),
            "forged_headers": self.send(
                [self.record(a_topic, "headers of site-a", site="site-a", edge="edge-a")]
            ),
            "site_a_key": self.send(
                [self.record(a_topic, "on site-a's key", site="site-a", edge="edge-a")],
                site="site-a",
                edge="edge-a",
                key="fleetlink/site-a/ingest/edge-a",
            ),
        }

    def foreign_topic(self) -> dict[str, Any]:
        """Honest about itself, but writes where the policy does not let site B write."""
        records = [self.record(t, f"into {t}") for t in self.spec["foreign_topics"]]
        return {"foreign": self.send([*records, self.record(self.spec["b_topic"], "own topic")])}

    def internal_topic(self) -> dict[str, Any]:
        """Writes straight into topics fleetlink owns (command topics, status, refused, _...)."""
        records = [self.record(t, f"into {t}") for t in self.spec["internal_topics"]]
        return {"internal": self.send(records)}

    def forged_registration(self) -> dict[str, Any]:
        """'tb4_01 is at site B' (and 'tb4_01 left'), while site A holds it."""
        event_fp = fingerprint(EVENT_SCHEMA)
        parsed = fastavro.parse_schema(dict(EVENT_SCHEMA))
        records = []
        for event in ("registered", "deregistered"):
            out = io.BytesIO()
            datum = {
                "robot": "tb4_01",
                "robot_type": "tb4",
                "site": self.site,
                "edge_id": self.edge,
                "event": event,
                "reason": MARKER,
                "timestamp": int(time.time() * 1000),
            }
            fastavro.schemaless_writer(out, parsed, datum)
            records.append(
                Record(
                    self.spec["registrations"],
                    b"tb4_01",
                    single_object(event_fp, out.getvalue()),
                    (("fleetlink.site", self.site.encode()), ("fleetlink.edge", self.edge.encode())),
                    int(time.time() * 1000),
                )
            )
        return {"claim": self.send(records, schemas={event_fp: json.dumps(EVENT_SCHEMA)})}

    def schema_poisoning(self) -> dict[str, Any]:
        """Site A's schema fingerprint with another text; then a text that differs only where the
        fingerprint does not look (a doc), under site B's own topic."""
        wrong = json.loads(self.string_text)
        wrong["fields"][0]["type"] = "long"
        lookalike = json.loads(self.string_text)
        lookalike["doc"] = f"{MARKER} lookalike"
        b_topic = self.spec["b_topic"]
        return {
            "wrong_text": self.send(
                [self.record(b_topic, "wrong text")], schemas={self.string_fp: json.dumps(wrong)}
            ),
            "lookalike": self.send(
                [self.record(b_topic, "lookalike text")], schemas={self.string_fp: json.dumps(lookalike)}
            ),
        }

    def forged_command(self) -> dict[str, Any]:
        """Commands put straight to site B's repeater: unsigned, signed with its own key, and a
        site A command key (which its router does not let through)."""
        ts = load_typestore("jazzy", [IROBOT])
        schema = avro_schema(ts, LIGHTRING, "jazzy")
        out = io.BytesIO()
        datum = {
            "header": {"stamp": {"sec": 0, "nanosec": 0}, "frame_id": ""},
            "leds": [{"red": 255, "green": 0, "blue": 255}] * 6,
            "override_system": True,
        }
        fastavro.schemaless_writer(out, fastavro.parse_schema(schema), datum)
        now = int(time.time() * 1000)
        results: dict[str, Any] = {}
        for name, robot in (("unsigned", "tb4_09"), ("own_key", "tb4_09"), ("site_a", "tb4_01")):
            env = CommandEnvelope(
                command_id=f"{MARKER}-{name}-{now}",
                robot=robot,
                ros_topic=f"/{robot}/cmd_lightring",
                ros_type=LIGHTRING,
                mapping="lightring",
                issued_at_ms=now,
                lease_until_ms=now + 3_600_000,  # an hour
                period_ms=1000,
                schema_fp=fingerprint(schema),
                body=out.getvalue(),
                schema=json.dumps(schema),
            )
            data = encode_envelope(env)
            site = "site-a" if name == "site_a" else self.site
            attachment = (
                sign_envelope(data, site, Ed25519PrivateKey.generate()) if name != "unsigned" else None
            )
            results[name] = self.query(f"fleetlink/{site}/command/{robot}/lightring", data, attachment)
        return results

    def open_admin(self) -> dict[str, Any]:
        """Change site B's edge over Zenoh without and with guessed tokens; guess its HTTP token."""
        key = f"fleetlink/{self.site}/admin/mappings?op=add"
        mapping = json.dumps({"name": MARKER, "robot_type": "tb4", "from": "/{robot}/x", "to": "x"}).encode()
        zenoh_answers = [
            self.query(key, mapping, None if i == 0 else f"Bearer guess-{i}".encode())["answers"]
            for i in range(20)
        ]
        statuses: list[int] = []
        for i in range(200):
            request = urllib.request.Request(
                f"{self.spec['admin_url']}/mappings", headers={"Authorization": f"Bearer guess-{i}"}
            )
            try:
                with urllib.request.urlopen(request, timeout=5) as response:
                    statuses.append(response.status)
            except urllib.error.HTTPError as exc:
                statuses.append(exc.code)
        return {"zenoh": zenoh_answers, "http": statuses}


ATTACKS = {
    "forged-site": Rogue.forged_site,
    "foreign-topic": Rogue.foreign_topic,
    "internal-topic": Rogue.internal_topic,
    "forged-registration": Rogue.forged_registration,
    "schema-poisoning": Rogue.schema_poisoning,
    "forged-command": Rogue.forged_command,
    "open-admin": Rogue.open_admin,
}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("attack", choices=sorted(ATTACKS))
    parser.add_argument("--spec", required=True, help="JSON: topics and names the attack needs")
    parser.add_argument("--cloud", help="the cloud router's TLS endpoint (with --certs)")
    parser.add_argument("--certs", type=Path, help="a directory holding ca.pem and site B's edge certificate")
    parser.add_argument("--site-router", help="site B's router (a client on the site network)")
    args = parser.parse_args(argv)
    spec = json.loads(args.spec)
    if args.cloud:
        from fleetlink.common.certs import CertBundle, IdentityFiles

        name = edge_name(spec.get("site", "site-b"))
        files = IdentityFiles(name, args.certs / f"{name}.pem", args.certs / f"{name}-key.pem")
        bundle = CertBundle(args.certs, args.certs / "ca.pem", {name: files})
        conf = client_config(args.cloud, bundle=bundle, identity=name)
    else:
        conf = client_config(args.site_router)
    with zenoh.open(conf) as session:
        rogue = Rogue(session, spec)
        rogue.wait_matching(spec["ready_key"])  # the routers propagated the target's queryable
        result = ATTACKS[args.attack](rogue)
    print(json.dumps(result), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
