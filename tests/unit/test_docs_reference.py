"""The configuration reference in docs/ is exactly what the config models generate."""

from __future__ import annotations

from fleetlink.cli.docgen import render
from tests.paths import DOCS

REFERENCE = DOCS / "reference" / "config.md"


def test_config_reference_is_current() -> None:
    assert REFERENCE.read_text() == render(), (
        "docs/reference/config.md is stale: run `python -m fleetlink.cli.docgen > docs/reference/config.md`"
    )


def test_reference_covers_every_kind_and_nested_keys() -> None:
    text = render()
    for heading in ("## edge", "## uplink", "## repeater"):
        assert heading in text
    for key in ("`spool.policy`", "`robot_types.<name>.mappings[].from`", "`kafka.producer_overrides`"):
        assert key in text
