"""The docs run: each document's runnable steps, in order, as a reader would type them
(``tests/integration/docs_scenario.py`` says what a step is and what the test changes: only
addresses and state folders). A step that fails names its document and line."""

from __future__ import annotations

import contextlib
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from fleetlink.common.zenoh_options import load_zenoh_file
from fleetlink.localstack.zenoh_router import ZenohRouter
from tests.helpers import free_port
from tests.integration.docs_scenario import (
    USUAL_PORTS,
    Step,
    load_yaml,
    router_config,
    service_config,
    service_overrides,
    split,
    steps,
    with_ports,
)
from tests.paths import ROOT

DOCS = [d for d in sorted([ROOT / "README.md", *(ROOT / "docs").rglob("*.md")]) if steps(d.read_text())]
STEP_TIMEOUT_S = 180.0
FIRST_OUTPUT_TIMEOUT_S = 60.0


def test_the_guides_have_scenarios() -> None:
    names = {str(d.relative_to(ROOT)) for d in DOCS}
    assert {"docs/guides/robot-integrator.md", "docs/guides/operator.md"} <= names
    for guide in ("robot-integrator", "operator"):
        kinds = {s.kind for s in steps((ROOT / "docs" / "guides" / f"{guide}.md").read_text())}
        assert {"run", "background"} <= kinds, guide


class Scenario:
    def __init__(self, doc: Path, folder: Path) -> None:
        self.doc = doc.relative_to(ROOT)
        self.folder = folder
        self.ports = {port: free_port() for port in USUAL_PORTS}
        env = {k: v for k, v in os.environ.items() if k not in ("FLEETLINK_SET", "FLEETLINK_MSG_PATH")}
        env["PATH"] = f"{Path(sys.executable).parent}{os.pathsep}{env.get('PATH', '')}"
        env["KAFKA_BOOTSTRAP"] = f"127.0.0.1:{self.ports[9092]}"
        env["SCHEMA_REGISTRY_URL"] = f"http://127.0.0.1:{self.ports[8081]}/apis/ccompat/v7"
        env["PYTHONUNBUFFERED"] = "1"
        self.env = env
        self.stack = contextlib.ExitStack()
        self.background: list[tuple[str, subprocess.Popen[bytes], Path]] = []

    def where(self, step: Step) -> str:
        return f"{self.doc}:{step.line}"

    # -- the steps -----------------------------------------------------------------------------

    def do(self, step: Step) -> None:
        if step.kind == "file":
            assert step.path.startswith("var/"), f"{self.where(step)}: a guide writes only under var/"
            path = ROOT / step.path
            path.parent.mkdir(parents=True, exist_ok=True)
            path.write_text(with_ports(step.text, self.ports))
        elif step.kind == "robots":
            self.robots(step)
        else:
            argv, env = self.command(step.text)
            if step.kind == "background":
                self.start(step, argv, env)
            else:
                self.run(step, argv, env)

    def command(self, text: str) -> tuple[list[str], dict[str, str]]:
        argv = split(with_ports(text, self.ports))
        env = dict(self.env)
        config = service_config(argv)
        if config is not None:
            data = load_yaml(ROOT / config)
            endpoints = self.zenoh_endpoints((data.get("zenoh") or {}).get("config_file"))
            lines = service_overrides(data, self.ports, self.folder / argv[1], endpoints)
            env["FLEETLINK_SET"] = "\n".join(lines)
        router = router_config(argv)
        if router is not None:
            for name, flag in (("listen", "-l"), ("connect", "-e")):
                for endpoint in self.zenoh_endpoints(router).get(name, []):
                    argv += [flag, with_ports(endpoint, self.ports)]
        if argv[:2] == ["fleetlink", "stack"] and "--dir" in argv:
            at = argv.index("--dir") + 1  # a state folder: the test's, so no earlier run's records
            argv[at] = str(self.folder / "stack" / Path(argv[at]).name)
            if argv[2] == "up":
                self.stack.callback(self.stack_down, argv[at])
        return argv, env

    def zenoh_endpoints(self, file: str | None) -> dict[str, list[str]]:
        if file is None:
            return {}
        conf = load_zenoh_file(ROOT / file)
        found = {}
        for name in ("listen", "connect"):
            value = json.loads(conf.get_json(f"{name}/endpoints"))
            found[name] = value.get("router", []) if isinstance(value, dict) else list(value)
        return found

    def run(self, step: Step, argv: list[str], env: dict[str, str]) -> None:
        result = subprocess.run(
            argv, cwd=ROOT, env=env, capture_output=True, text=True, timeout=STEP_TIMEOUT_S, check=False
        )
        assert result.returncode == 0, (
            f"{self.where(step)}: `{step.text}` exited {result.returncode}:\n"
            f"{result.stdout[-1500:]}\n{result.stderr[-2500:]}\n{self.logs()}"
        )

    def start(self, step: Step, argv: list[str], env: dict[str, str]) -> None:
        log = self.folder / f"step-{step.line}.log"
        with log.open("wb") as out:
            proc = subprocess.Popen(
                argv, cwd=ROOT, env=env, stdout=out, stderr=subprocess.STDOUT, start_new_session=True
            )
        self.background.append((step.text, proc, log))
        deadline = time.monotonic() + FIRST_OUTPUT_TIMEOUT_S
        while log.stat().st_size == 0 and proc.poll() is None and time.monotonic() < deadline:
            time.sleep(0.1)  # ok-sleep: waiting for the background command's first words
        assert proc.poll() is None, (
            f"{self.where(step)}: `{step.text}` exited {proc.returncode}:\n{_tail(log)}"
        )

    def robots(self, step: Step) -> None:
        endpoint = with_ports(step.text, self.ports)
        router = self.stack.enter_context(ZenohRouter(int(endpoint.rsplit(":", 1)[1])))
        sim = Step("background", "", step.line)
        argv = ["fleetlink", "ros", "sim", "--robots", "2", "-m", "client", "-e", router.endpoint]
        self.start(sim, argv, self.env)

    # -- the end -------------------------------------------------------------------------------

    def stack_down(self, folder: str) -> None:
        subprocess.run(
            ["fleetlink", "stack", "down", "--dir", folder], cwd=ROOT, env=self.env, timeout=60, check=False
        )

    def logs(self) -> str:
        return "\n".join(f"--- `{text}`\n{_tail(log)}" for text, _proc, log in self.background)

    def close(self) -> None:
        for _text, proc, _log in reversed(self.background):
            if proc.poll() is None:
                with contextlib.suppress(ProcessLookupError):
                    os.killpg(proc.pid, signal.SIGTERM)
                try:
                    proc.wait(20)
                except subprocess.TimeoutExpired:
                    os.killpg(proc.pid, signal.SIGKILL)
                    proc.wait(5)
        self.stack.close()


def _tail(path: Path, lines: int = 15) -> str:
    return "\n".join(path.read_text(errors="replace").splitlines()[-lines:])


@pytest.mark.parametrize("doc", DOCS, ids=lambda d: str(d.relative_to(ROOT)))
def test_the_doc_runs(doc: Path, tmp_path: Path) -> None:
    scenario = Scenario(doc, tmp_path)
    try:
        for step in steps(doc.read_text()):
            scenario.do(step)
    finally:
        scenario.close()
