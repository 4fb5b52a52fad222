"""Where the native data plane connects: the router the robots' data flows through."""

from __future__ import annotations

from typing import Any

import pytest

from fleetlink.edge.runtime.dataplane import dataplane_config
from fleetlink.edge.runtime.errors import RuntimeSetupError


def _conf(mode: str, listen: list[str], connect: list[str]) -> dict[str, Any]:
    return {"mode": mode, "listen": {"endpoints": listen}, "connect": {"endpoints": connect}}


def test_a_site_router_edge_receives_through_its_own_listeners() -> None:
    # the edge is the site's router (deploy/edge.example.yaml, deploy/compose/edge.yaml): robots
    # connect to its listener; what it connects to is the cloud router, which carries no robot data
    conf = dataplane_config(_conf("router", ["tcp/0.0.0.0:7447"], ["tcp/cloud:7447"]))
    assert conf["connect"]["endpoints"] == ["tcp/127.0.0.1:7447"]
    assert conf["mode"] == "client"
    assert conf["listen"]["endpoints"] == []


@pytest.mark.parametrize("mode", ["peer", "client"])
def test_other_edges_receive_through_the_routers_they_connect_to(mode: str) -> None:
    conf = dataplane_config(_conf(mode, ["tcp/127.0.0.1:0"], ["tcp/10.0.0.5:7447", "tcp/cloud:7448"]))
    assert conf["connect"]["endpoints"] == ["tcp/10.0.0.5:7447", "tcp/cloud:7448"]


def test_a_router_without_fixed_listeners_uses_what_it_connects_to() -> None:
    conf = dataplane_config(_conf("router", ["tcp/127.0.0.1:0"], ["tcp/10.0.0.5:7447"]))
    assert conf["connect"]["endpoints"] == ["tcp/10.0.0.5:7447"]


def test_nothing_to_connect_to_is_an_error() -> None:
    with pytest.raises(RuntimeSetupError, match=r"zenoh\.connect"):
        dataplane_config(_conf("peer", ["tcp/127.0.0.1:0"], []))
