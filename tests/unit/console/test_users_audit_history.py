"""Named users and their sessions, the audit record, the history kept for charts, command
values completed from their schema: the console's pure parts."""

from __future__ import annotations

from typing import Any

import pytest
from pydantic import SecretStr

from fleetlink.console.audit import MemoryAudit, audit_entry
from fleetlink.console.auth import TOKEN_USER, Authenticator, Identity
from fleetlink.console.envelope import Envelope
from fleetlink.console.errors import ConsoleConfigError
from fleetlink.console.history import History
from fleetlink.console.kafka_ops import fill_datum
from fleetlink.console.operations import CommandRefusedError
from fleetlink.console.rates import RateBoard
from fleetlink.console.sampler import site_points
from fleetlink.console.users import User, hash_password, parse_users, role_at_least, verify_password
from fleetlink.console.views import site_figures, site_view

pytestmark = pytest.mark.unit

ADA = hash_password("admin-pass-1", salt=b"0123456789abcdef")
LIN = hash_password("operator-pass-1", salt=b"fedcba9876543210")


def users() -> dict[str, User]:
    return parse_users(
        {
            "users": [
                {"name": "ada", "role": "admin", "password_hash": ADA},
                {"name": "lin", "role": "operator", "password_hash": LIN},
            ]
        },
        source="users.yaml",
    )


def test_passwords_are_kept_as_scrypt_hashes() -> None:
    assert ADA.startswith("scrypt$16384$8$1$")
    assert "admin-pass-1" not in ADA
    assert verify_password(ADA, "admin-pass-1")
    assert not verify_password(ADA, "admin-pass-2")
    assert not verify_password("plain-text", "plain-text")
    assert hash_password("x") != hash_password("x")  # salted


def test_roles_nest() -> None:
    assert role_at_least("admin", "operator")
    assert role_at_least("operator", "viewer")
    assert not role_at_least("viewer", "operator")
    assert not role_at_least("root", "viewer")


@pytest.mark.parametrize(
    ("entry", "problem"),
    [
        ({"name": "a b", "role": "viewer", "password_hash": ADA}, "users[0].name"),
        ({"name": "ab", "role": "root", "password_hash": ADA}, "users[0].role"),
        ({"name": "ab", "role": "viewer", "password_hash": "secret"}, "users[0].password_hash"),
        ({"name": "ab", "role": "viewer", "password_hash": ADA, "pw": 1}, "users[0].pw"),
    ],
)
def test_a_users_file_that_does_not_validate_names_the_path(entry: dict[str, Any], problem: str) -> None:
    with pytest.raises(ConsoleConfigError, match=problem.replace("[", r"\[").replace("]", r"\]")):
        parse_users({"users": [entry]}, source="users.yaml")


def test_sessions_expire_and_end_when_the_password_changes() -> None:
    auth = Authenticator(SecretStr("t" * 32), users(), ttl_s=60, secret=b"k" * 32)
    lin = auth.sign_in("lin", "operator-pass-1")
    assert lin == Identity("lin", "operator")
    assert auth.sign_in("lin", "wrong") is None
    assert auth.sign_in("nobody", "operator-pass-1") is None
    assert auth.sign_in("", "t" * 32) == Identity(TOKEN_USER, "admin")
    cookie = auth.cookie(lin, now=1000.0)
    who, tried = auth.identify(authorization=None, cookie=cookie, now=1059.0)
    assert (who, tried) == (Identity("lin", "operator", by_cookie=True), False)
    assert auth.identify(authorization=None, cookie=cookie, now=1060.0)[0] is None  # expired
    forged = cookie.rsplit("~", 1)[0] + "~" + "0" * 64
    assert auth.identify(authorization=None, cookie=forged, now=1001.0)[0] is None
    changed = Authenticator(
        SecretStr("t" * 32),
        {**users(), "lin": User("lin", "operator", hash_password("new-pass-2"))},
        ttl_s=60,
        secret=b"k" * 32,
    )
    assert changed.identify(authorization=None, cookie=cookie, now=1001.0)[0] is None
    assert auth.identify(authorization="Basic bGluOm9wZXJhdG9yLXBhc3MtMQ==", cookie=None, now=0)[0] == lin


def test_an_audit_record_says_who_what_and_when() -> None:
    entry = audit_entry(
        Identity("lin", "operator"),
        "mapping.add",
        process="uplink",
        at=5.0,
        site="a",
        target="ir",
        status=201,
    )
    assert entry == {
        "at": 5.0,
        "user": "lin",
        "role": "operator",
        "process": "uplink",
        "action": "mapping.add",
        "site": "a",
        "target": "ir",
        "status": 201,
        "ok": True,
        "detail": {},
    }
    audit = MemoryAudit(keep=2)
    for n in range(3):
        assert audit.record({**entry, "at": float(n)}) is None
    assert [r["at"] for r in audit.recent()] == [2.0, 1.0]


def test_history_keeps_one_point_per_step_for_the_window() -> None:
    history = History(window_s=100, step_s=10)
    assert history.add(("site", "a"), {"acked": 1.0}, 0)
    assert not history.add(("site", "a"), {"acked": 2.0}, 3)  # too soon
    assert history.add(("site", "a"), {"acked": 3.0, "backlog": 7}, 10)
    assert history.add(("mapping", "a", "ir"), {"emitted": 1.0}, 10)
    assert history.points(("site", "a"), 10) == {
        "all": {"t": [0, 10], "acked": [1.0, 3.0], "backlog": [None, 7]}
    }
    assert history.points(("site", "a"), 105) == {"all": {"t": [10], "acked": [3.0], "backlog": [7]}}
    assert list(history.points(("mapping", "a"), 10)) == ["ir"]


def test_a_site_view_gives_a_site_point_and_one_per_mapping() -> None:
    view = {
        "site": "a",
        "mappings": [
            {"name": "ir", "rates": {"received": 4.0, "emitted": 2.0, "filtered": 2.0}},
            {"name": "imu", "rates": {"received": 1.0, "emitted": None}},
        ],
        "graph": {"backlog": {"records": 12, "oldest_age_s": 3.5}},
        "delivery": {"rate": 2.0},
    }
    points = site_points(view)
    assert points[("site", "a")]["received"] == 5.0
    assert points[("site", "a")]["emitted"] == 2.0
    assert (points[("site", "a")]["acked"], points[("site", "a")]["backlog"]) == (2.0, 12)
    assert points[("mapping", "a", "imu")]["emitted"] is None


def _parts(received: int, depth: int) -> dict[str, Envelope]:
    mapping = {"name": "imu", "counters": {"received": received, "emitted": received // 2, "dropped": 1}}
    streams = [{"stream": "durable", "depth": depth, "bytes": 10 * depth, "oldest_age_s": 2.5}]
    robots = [{"robot": f"/r{n}", "robot_type": "tb4"} for n in range(50)]
    return {
        "mappings": Envelope(status=200, site="a", edge_id="e", body=[mapping]),
        "status": Envelope(status=200, site="a", edge_id="e", body={"streams": streams}),
        "robots": Envelope(status=200, site="a", edge_id="e", body=robots),
    }


def test_the_history_figures_are_those_of_the_site_page() -> None:
    """The sampler reads a site's mappings and status only (its robots and topics grow with the
    fleet): its points are those a full site view gives."""
    cheap, full = RateBoard(window_s=25, min_span_s=5), RateBoard(window_s=25, min_span_s=5)
    delivery = [{"uplink": "u", "topics": {}}]
    for now, received, depth in ((0.0, 100, 7), (10.0, 600, 9)):
        parts = _parts(received, depth)
        figures = site_points(site_figures("a", parts, cheap, now=now, delivery=delivery))
        view = site_points(site_view("a", _parts(received, depth), full, now=now, delivery=delivery))
        assert figures == view
    assert figures[("site", "a")]["received"] == 50.0
    assert figures[("site", "a")]["backlog"] == 9
    assert figures[("mapping", "a", "imu")]["emitted"] == 25.0


LED = {
    "type": "record",
    "name": "Led",
    "fields": [{"name": "red", "type": "int"}, {"name": "on", "type": "boolean"}],
}
RING = {
    "type": "record",
    "name": "Ring",
    "fields": [
        {"name": "leds", "type": {"type": "array", "items": LED}},
        {"name": "first", "type": "Led"},
        {"name": "note", "type": ["null", "string"]},
    ],
}


def test_a_command_value_is_completed_with_defaults() -> None:
    filled = fill_datum(RING, {"leds": [{"red": 255}]})
    assert filled == {"leds": [{"red": 255, "on": False}], "first": {"red": 0, "on": False}, "note": None}
    with pytest.raises(CommandRefusedError, match="leds"):
        fill_datum(RING, {"leds": "red"})
    with pytest.raises(CommandRefusedError, match="colour"):
        fill_datum(RING, {"colour": 1})


def test_the_command_line_prints_a_hash_of_the_password_on_stdin(
    monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    import io

    from fleetlink.cli import main

    monkeypatch.setattr("sys.stdin", io.StringIO("a-long-password\n"))
    assert main(["console", "hash-password"]) == 0
    printed = capsys.readouterr().out.strip()
    assert verify_password(printed, "a-long-password")
    monkeypatch.setattr("sys.stdin", io.StringIO("short\n"))
    assert main(["console", "hash-password"]) == 2
    assert "at least 8 characters" in capsys.readouterr().err
