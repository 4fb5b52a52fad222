"""The warehouse demo end to end (issue 8): fault → one red command, heal → one green, nothing else.

The same loop, judged the same way, with either fault-detection app: the Quix Streams one
(Python, in the demo's process) and the Kafka Streams one (Java, built with Maven, its own process).
"""

from __future__ import annotations

import io
from pathlib import Path
from typing import Literal

import pytest

from fleetlink.demo.runner import Demo, DemoOptions


@pytest.mark.parametrize("app", ["python", "java"])
def test_demo_closes_the_loop(
    app: Literal["python", "java"],
    kafka_bootstrap: str,
    schema_registry_url: str,
    tmp_path: Path,
    request: pytest.FixtureRequest,
) -> None:
    if app == "java":
        request.getfixturevalue("kafka_streams_jar")  # built here with Maven, so the demo need not
    out = io.StringIO()
    demo = Demo(
        DemoOptions(
            workdir=tmp_path / "demo",
            robots=3,
            bootstrap=kafka_bootstrap,
            registry_url=schema_registry_url,
            out=out,
            step_timeout_s=60,
            app=app,
        )
    )
    summary = demo.run()
    told = out.getvalue()

    faulted = summary["faulted_robot"]
    # exactly one "failure" command after the fault and one "recovered" command after healing
    assert summary["commands"] == {faulted: ["red", "green"]}, told
    # healthy robots (one of them had a single spurious failure reading) received none
    assert set(summary["healthy_robots_without_commands"]) == {"tb4_01", "tb4_03", "tb4_04"}
    assert "glitch: one spurious" in told
    # a robot joining during the run was picked up without restarting anything
    assert summary["joined_mid_run"] == "tb4_04"
    assert "tb4_04" in summary["registered"]
    assert summary["loop_closed"] is True
    assert 0 < summary["fault_to_red_led_s"] < 30
    assert 0 < summary["heal_to_green_led_s"] < 30
    assert (tmp_path / "demo" / "summary.json").exists()
    assert "stopped" in told.splitlines()[-1]
    # both registry URLs are told, each with what it is for
    native = schema_registry_url.replace("/apis/ccompat/v7", "/apis/registry/v3")
    assert f"registry {schema_registry_url}   Confluent-compatible API" in told
    assert f"registry {native}   Apicurio native API" in told
    if app == "java":
        assert "fault-detection app: Kafka Streams (Java)" in told
        assert f"fault detection: {faulted} is now failed" in told
        assert f"fault detection: {faulted} is now running" in told
