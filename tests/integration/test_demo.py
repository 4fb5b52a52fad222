"""The warehouse demo end to end (issue 8): fault → one red command, heal → one green, nothing else.

The same loop, judged the same way, with either fault-detection app: the Quix Streams one
(Python, in the demo's process) and the Kafka Streams one (Java, built with Maven, its own process).
"""

from __future__ import annotations

import io
import re
import threading
from pathlib import Path
from typing import Any, Literal

import httpx
import pytest

from fleetlink.demo.runner import Demo, DemoOptions
from tests.helpers import wait_until


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
            usual_ports=False,  # other tests' services may hold 8480, 8490, 9464 meanwhile
        )
    )
    result: dict[str, Any] = {}

    def run() -> None:
        try:
            result["summary"] = demo.run()
        except BaseException as exc:  # noqa: BLE001 - handed to the test's thread, which fails with it
            result["error"] = exc

    def failed() -> None:
        error = result.get("error")
        if error is not None:  # the demo failed: say why now, not when a wait runs out
            raise AssertionError(f"the demo failed: {error!r}\n{out.getvalue()}") from error

    def told_urls() -> bool:
        failed()
        return "metrics: " in out.getvalue()

    runner = threading.Thread(target=run)
    runner.start()
    try:
        wait_until(told_urls, timeout=120, message="the demo's URLs told")
        _consoles_and_metrics_answer(out.getvalue(), demo.token)
    finally:
        runner.join(300)
    failed()
    summary = result["summary"]
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
    lines = told.splitlines()
    assert lines[-2].endswith("stopping everything the demo started ...")
    assert lines[-1].endswith("] stopped")  # nothing told after it, nothing between
    assert "summary written to" in lines[-3]

    # both registry URLs are told, each with what it is for
    native = schema_registry_url.replace("/apis/ccompat/v7", "/apis/registry/v3")
    assert f"registry {schema_registry_url}   Confluent-compatible API" in told
    assert f"registry {native}   Apicurio native API" in told
    if app == "java":
        assert "fault-detection app: Kafka Streams (Java)" in told
        assert f"fault detection: {faulted} is now failed" in told
        assert f"fault detection: {faulted} is now running" in told


def _consoles_and_metrics_answer(told: str, token: str) -> None:
    consoles = re.search(r"web console: (http://\S+/console/) \(the fleet\), (http://\S+/console/)", told)
    assert consoles is not None, told
    assert f"sign in with token {token}" in told
    for console in consoles.groups():
        assert httpx.get(console + "login", timeout=10).status_code == 200
        bearer = {"Authorization": f"Bearer {token}"}
        page = httpx.get(console, headers=bearer, timeout=10, follow_redirects=True)
        assert page.status_code == 200, console
        assert httpx.get(console + "api/sites", timeout=10).status_code == 401  # the token is needed
    metrics = re.findall(r"(http://\S+/metrics) \(", told)
    assert len(metrics) == 2, told
    for url in metrics:
        scrape = httpx.get(url, timeout=10)
        assert scrape.status_code == 200
        assert "fleetlink_" in scrape.text
