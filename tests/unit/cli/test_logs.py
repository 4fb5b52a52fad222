"""Logging of the ``fleetlink`` command: quiet tools, INFO for services, JSON lines on request,
dependencies' warnings only at DEBUG."""

from __future__ import annotations

import json
import logging
import warnings

import pytest

from fleetlink.cli import build_parser
from fleetlink.cli.logs import SERVICE_VERBOSITY, JsonFormatter, configure_logging, level_for


def test_levels() -> None:
    assert [level_for(v) for v in (0, 1, 2, 5)] == [
        logging.WARNING,
        logging.INFO,
        logging.DEBUG,
        logging.DEBUG,
    ]


@pytest.mark.parametrize(
    ("argv", "verbosity"),
    [
        (["ros", "graph"], 0),
        (["validate", "x.yaml"], 0),
        (["edge", "run", "-c", "x.yaml"], SERVICE_VERBOSITY),
        (["uplink", "run", "-c", "x.yaml"], SERVICE_VERBOSITY),
        (["repeater", "run", "-c", "x.yaml"], SERVICE_VERBOSITY),
        (["zenoh", "router", "-c", "x.json5"], SERVICE_VERBOSITY),
    ],
)
def test_services_log_info_and_tools_only_warnings(argv: list[str], verbosity: int) -> None:
    assert getattr(build_parser().parse_args(argv), "log_verbosity", 0) == verbosity


def test_json_lines() -> None:
    record = logging.LogRecord("fleetlink.edge", logging.INFO, __file__, 1, "robot %s up", ("tb4_01",), None)
    entry = json.loads(JsonFormatter().format(record))
    assert (entry["level"], entry["logger"], entry["message"]) == (
        "info",
        "fleetlink.edge",
        "robot tb4_01 up",
    )


def test_warnings_of_dependencies_go_to_debug(caplog: pytest.LogCaptureFixture) -> None:
    with warnings.catch_warnings():
        configure_logging(0)
        with caplog.at_level(logging.DEBUG, logger="py.warnings"):
            warnings.warn_explicit("old api", DeprecationWarning, "/x/site-packages/lib/mod.py", 3)
            warnings.warn_explicit("our own", UserWarning, "/src/fleetlink/edge/agent.py", 4)
    levels = {r.getMessage().split(": ")[-1].split("\n")[0]: r.levelno for r in caplog.records}
    assert levels["old api"] == logging.DEBUG
    assert levels["our own"] == logging.WARNING
