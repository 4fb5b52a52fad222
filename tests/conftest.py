"""Test layout: tests/unit (no sockets), tests/integration (real services), tests/fault.

Tests are marked by folder, so ``-m unit`` runs only the pure ones. Service fixtures
(Kafka, schema registry, Zenoh routers) live in tests/fixtures and are loaded here.
"""

from __future__ import annotations

from pathlib import Path

import pytest
from hypothesis import HealthCheck, settings

# Property tests judge results, never speed: a per-example deadline or a "too slow" data check
# measures the machine's load (a loaded run once took 327 ms for an example that takes 0.6 ms)
settings.register_profile("fleetlink", deadline=None, suppress_health_check=[HealthCheck.too_slow])
settings.load_profile("fleetlink")

pytest_plugins = ["tests.fixtures.services"]

TESTS = Path(__file__).parent


def pytest_collection_modifyitems(items: list[pytest.Item]) -> None:
    for item in items:
        rel = Path(str(item.fspath)).relative_to(TESTS).parts
        if rel and rel[0] in ("unit", "integration", "fault", "browser"):
            item.add_marker(getattr(pytest.mark, rel[0]))
