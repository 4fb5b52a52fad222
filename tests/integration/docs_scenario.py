"""The docs' runnable parts as scenarios: each document's steps run in order, as a reader would.

A document's steps, in the order they appear:

* a ```` ```sh runnable ```` block: one command per line (``  # comment`` ignored); a line
  ending in `` &`` is started in the background and kept until the document's last step (its
  first line of output, or its exit, ends the wait for it);
* a ```` ```yaml file=PATH ```` block: the reader saves it as ``PATH`` (under ``var/``);
* ``<!-- runnable: simulated robots on ENDPOINT -->``: the reader's robots, which the test
  stands in for with a Zenoh router on ``ENDPOINT`` and ``fleetlink ros sim`` robots behind it.

Addresses are the only thing the test changes: the docs use the usual ports (7447 robots' router,
7448 cloud router, 9092 Kafka, 8081 registry, 8480 edge admin, 8490 fleet console, 9464 uplink
metrics, 9465 repeater metrics); the test puts each on a free port, in commands and saved files
by text, in the configs a service loads by ``$FLEETLINK_SET`` (the product's own override), and
in ``$KAFKA_BOOTSTRAP`` / ``$SCHEMA_REGISTRY_URL`` (the defaults of ``fleetlink kafka echo``).
State folders — those a service config names, and ``fleetlink stack --dir`` — go to the test's
folder, so a run never reads an earlier run's records. This module's parsing and rewriting are pure.
"""

from __future__ import annotations

import re
import shlex
from collections.abc import Iterator, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import yaml

from fleetlink.common.yaml_paths import format_path

USUAL_PORTS = (7447, 7448, 9092, 8081, 8480, 8490, 9464, 9465)
STATE_KEYS = (("spool", "dir"), ("repeater", "state_dir"))

_STEP = re.compile(
    r"^```sh runnable\n(?P<sh>.*?)^```"
    r"|^```yaml file=(?P<path>\S+)\n(?P<yaml>.*?)^```"
    r"|<!-- runnable: simulated robots on (?P<robots>\S+) -->",
    re.MULTILINE | re.DOTALL,
)


@dataclass(frozen=True)
class Step:
    kind: str  # "run", "background", "file", "robots"
    text: str  # the command, the file's text, or the robots' endpoint
    line: int  # where it is in the document
    path: str = ""  # for "file"


def steps(doc: str) -> list[Step]:
    found: list[Step] = []
    for match in _STEP.finditer(doc):
        line = doc.count("\n", 0, match.start()) + 1
        if match.group("robots"):
            found.append(Step("robots", match.group("robots"), line))
        elif match.group("path"):
            found.append(Step("file", match.group("yaml"), line, match.group("path")))
        else:
            for offset, raw in enumerate(match.group("sh").splitlines(), start=1):
                command = raw.split("  #", 1)[0].strip()
                if not command:
                    continue
                background = command.endswith(" &")
                found.append(
                    Step(
                        "background" if background else "run",
                        command.removesuffix(" &").strip(),
                        line + offset,
                    )
                )
    return found


def with_ports(text: str, ports: Mapping[int, int]) -> str:
    """Every usual port in ``text`` (as a whole number) replaced by the test's."""
    return re.sub(r"(?<![\d.])(\d{4})(?![\d.])", lambda m: str(ports.get(int(m.group(1)), m.group(1))), text)


def _strings(data: Any, at: tuple[str | int, ...] = ()) -> Iterator[tuple[tuple[str | int, ...], Any]]:
    if isinstance(data, dict):
        for key, value in data.items():
            yield from _strings(value, (*at, key))
    elif isinstance(data, list):
        for i, value in enumerate(data):
            yield from _strings(value, (*at, i))
    else:
        yield at, data


def service_overrides(
    config: Any, ports: Mapping[int, int], state: Path, zenoh_endpoints: Mapping[str, list[str]]
) -> list[str]:
    """``KEY=VALUE`` lines for ``$FLEETLINK_SET`` that move a service config's addresses to the
    test's ports and its state folders into ``state``; ``zenoh_endpoints`` are the listen and
    connect endpoints of the Zenoh config file it names, if any."""
    lines = []
    for path, value in _strings(config):
        if isinstance(value, str | int) and with_ports(str(value), ports) != str(value):
            lines.append(f"{format_path(path)}={with_ports(str(value), ports)}")
    for section, key in STATE_KEYS:
        if isinstance(config.get(section), dict) and key in config[section]:
            lines.append(f"{section}.{key}={state / section}")
    zenoh = config.get("zenoh") or {}
    for name, endpoints in zenoh_endpoints.items():
        moved = [with_ports(e, ports) for e in endpoints]
        if moved != endpoints and name not in zenoh:
            lines.append(f"zenoh.{name}=[{', '.join(moved)}]")
    return lines


def service_config(argv: list[str]) -> str | None:
    """The config file of ``fleetlink edge|uplink|repeater run -c FILE``, if that is the command."""
    if (
        len(argv) > 3
        and argv[0] == "fleetlink"
        and argv[1] in ("edge", "uplink", "repeater")
        and argv[2] == "run"
    ):
        return argv[argv.index("-c") + 1] if "-c" in argv else None
    return None


def router_config(argv: list[str]) -> str | None:
    if argv[:3] == ["fleetlink", "zenoh", "router"] and "-c" in argv:
        return argv[argv.index("-c") + 1]
    return None


def load_yaml(path: Path) -> Any:
    return yaml.safe_load(path.read_text())


def split(command: str) -> list[str]:
    return shlex.split(command)
