"""How the docs test reads a document's steps and moves their addresses (pure parts)."""

from __future__ import annotations

from pathlib import Path

from tests.integration.docs_scenario import (
    router_config,
    service_config,
    service_overrides,
    steps,
    with_ports,
)

DOC = """\
# Guide
<!-- runnable: simulated robots on tcp/127.0.0.1:7447 -->
```sh runnable
fleetlink stack up --kafka-port 9092   # the stack
fleetlink uplink run -c deploy/uplink.example.yaml &

fleetlink probe http://127.0.0.1:8480/health --wait 30
```
```yaml file=var/g/edge.yaml
site: a
```
```sh
fleetlink not-run
```
"""

PORTS = {7447: 17447, 7448: 17448, 9092: 19092, 8081: 18081, 8480: 18480}


def test_steps_in_order() -> None:
    found = [(s.kind, s.text, s.line) for s in steps(DOC)]
    assert found == [
        ("robots", "tcp/127.0.0.1:7447", 2),
        ("run", "fleetlink stack up --kafka-port 9092", 4),
        ("background", "fleetlink uplink run -c deploy/uplink.example.yaml", 5),
        ("run", "fleetlink probe http://127.0.0.1:8480/health --wait 30", 7),
        ("file", "site: a\n", 9),
    ]
    assert steps(DOC)[-1].path == "var/g/edge.yaml"


def test_only_the_usual_ports_move() -> None:
    assert with_ports("tcp/127.0.0.1:7447 --kafka-port 9092 v1.2.7447 12345 8480", PORTS) == (
        "tcp/127.0.0.1:17447 --kafka-port 19092 v1.2.7447 12345 18480"
    )


def test_service_configs_get_their_addresses_and_state_moved() -> None:
    config = {
        "kafka": {"bootstrap_servers": "127.0.0.1:9092"},
        "zenoh": {"connect": ["tcp/127.0.0.1:7448"]},
        "spool": {"dir": "var/edge/spool"},
        "site": "warehouse-a",
    }
    lines = service_overrides(config, PORTS, Path("state"), {"listen": ["tcp/127.0.0.1:7447"]})
    assert lines == [
        "kafka.bootstrap_servers=127.0.0.1:19092",
        "zenoh.connect[0]=tcp/127.0.0.1:17448",
        "spool.dir=state/spool",
        "zenoh.listen=[tcp/127.0.0.1:17447]",
    ]


def test_which_commands_load_configs() -> None:
    assert service_config(["fleetlink", "edge", "run", "-c", "e.yaml"]) == "e.yaml"
    assert service_config(["fleetlink", "validate", "e.yaml"]) is None
    assert router_config(["fleetlink", "zenoh", "router", "-c", "r.json5"]) == "r.json5"
