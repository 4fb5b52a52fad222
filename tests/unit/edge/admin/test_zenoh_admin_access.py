"""Who may do what in the Zenoh admin space: read-only without a token, locked out after guesses."""

from __future__ import annotations

from typing import Any, cast

import zenoh
from pydantic import SecretStr

from fleetlink.edge.admin.service import AdminService
from fleetlink.edge.admin.space import Target
from fleetlink.edge.admin.zenoh_admin import ZenohAdmin


class Service:
    site = "site-a"


def admin(token: str | None) -> ZenohAdmin:
    service = cast(AdminService, Service())
    session = cast(zenoh.Session, object())
    return ZenohAdmin(session, service, edge_id="edge-1", token=SecretStr(token) if token else None)


READ = [Target("fleetlink/site-a/admin/mappings", "mappings")]
CHANGE = [Target("fleetlink/site-a/admin/mappings/ir", "mappings", "ir", "delete")]


def test_without_a_token_the_space_is_read_only() -> None:
    a = admin(None)
    assert a._denied(None, READ) is None
    denied: Any = a._denied(None, CHANGE)
    assert denied[0] == 403
    assert "need an admin token" in denied[1]
    assert a.refused_changes == 1


def test_wrong_tokens_lock_the_space_out() -> None:
    a = admin("t0ken")
    assert a._denied(b"Bearer t0ken", CHANGE) is None
    statuses = [(a._denied(f"Bearer guess-{i}".encode(), READ) or (0, ""))[0] for i in range(50)]
    assert statuses[:5] == [401] * 5
    assert set(statuses[5:]) == {429}
    assert (a._denied(b"Bearer t0ken", READ) or (0, ""))[0] == 429
