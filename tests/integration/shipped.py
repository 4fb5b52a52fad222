"""Shipped configs run as real processes: ``python -m fleetlink ...`` with only addresses and
state folders changed by ``--set``, started and stopped in one ``ExitStack``.

Used by the tests of ``deploy/`` and of the guides. Every process writes to its own log under
the test's folder; a process that does not come up fails the test with the tail of its log.
"""

from __future__ import annotations

import contextlib
import json
import subprocess
import sys
import threading
import time
from collections.abc import Callable
from pathlib import Path
from types import TracebackType
from typing import Any

from fleetlink.localstack.process import ServerProcess, log_tail
from tests.helpers import free_port
from tests.paths import ROOT

START_TIMEOUT_S = 60.0


def fleetlink(*args: str) -> list[str]:
    return [sys.executable, "-m", "fleetlink", *args]


def endpoint() -> str:
    return f"tcp/127.0.0.1:{free_port()}"


def address() -> str:
    return f"127.0.0.1:{free_port()}"


def in_log(path: Path, text: str) -> Callable[[], bool]:
    def ready() -> bool:
        try:
            return text in path.read_text(errors="replace")
        except OSError:
            return False

    return ready


def answers(url: str) -> Callable[[], bool]:
    """Ready when ``fleetlink probe URL`` (the containers' healthcheck) exits 0."""

    def ready() -> bool:
        probe = subprocess.run(fleetlink("probe", url), capture_output=True, timeout=30, check=False)
        return probe.returncode == 0

    return ready


class Bed:
    """The processes of one test, run from the repository's top (the configs' relative paths)."""

    def __init__(self, folder: Path) -> None:
        self.folder = folder
        self._stack = contextlib.ExitStack()
        self.logs: dict[str, Path] = {}

    def start(self, name: str, args: list[str], ready: Callable[[], bool] | None = None) -> Path:
        """Start ``fleetlink ARGS``; returns its log once ``ready`` (default: the log says
        anything) holds."""
        log = self.folder / f"{name}.log"
        self.logs[name] = log
        proc = ServerProcess(
            name=name,
            argv=fleetlink(*args),
            log_path=log,
            pid_path=self.folder / f"{name}.pid",
            ready=ready or (lambda: log.exists() and log.stat().st_size > 0),
            env={"PYTHONUNBUFFERED": "1"},
            cwd=ROOT,
        )
        proc.start(START_TIMEOUT_S)
        self._stack.callback(proc.stop)
        return log

    def run(self, *args: str, timeout: float = 120.0) -> subprocess.CompletedProcess[str]:
        """Run ``fleetlink ARGS`` to its end."""
        return subprocess.run(
            fleetlink(*args), cwd=ROOT, capture_output=True, text=True, timeout=timeout, check=False
        )

    def follow(self, topic: str, bootstrap: str, registry: str) -> Records:
        """``fleetlink kafka echo TOPIC`` in the background: the records that arrive from now on."""
        argv = fleetlink("kafka", "echo", topic, "-b", bootstrap, "--registry", registry)
        records = Records(subprocess.Popen(argv, cwd=ROOT, stdout=subprocess.PIPE, text=True))
        self._stack.callback(records.stop)
        return records

    def tails(self) -> str:
        return "\n".join(f"--- {name}\n{log_tail(path, 15)}" for name, path in self.logs.items())

    def wait(self, predicate: Callable[[], bool], timeout: float, what: str) -> None:
        deadline = time.monotonic() + timeout
        while not predicate():
            if time.monotonic() > deadline:
                raise AssertionError(f"timed out after {timeout:.0f} s waiting for: {what}\n{self.tails()}")
            time.sleep(0.2)  # ok-sleep: polling processes of the bed

    def __enter__(self) -> Bed:
        return self

    def __exit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        self._stack.close()


class Records:
    """The JSON lines a ``fleetlink kafka echo`` process prints, collected by a thread."""

    def __init__(self, proc: subprocess.Popen[str]) -> None:
        self.proc = proc
        self._lock = threading.Lock()
        self._records: list[dict[str, Any]] = []
        self._thread = threading.Thread(target=self._read, daemon=True)
        self._thread.start()

    def _read(self) -> None:
        assert self.proc.stdout is not None
        for line in self.proc.stdout:
            with self._lock:
                self._records.append(json.loads(line))

    def of(self, key: str) -> list[dict[str, Any]]:
        with self._lock:
            return [r for r in self._records if r["key"] == key]

    def stop(self) -> None:
        self.proc.terminate()
        try:
            self.proc.wait(10)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            self.proc.wait(5)
        self._thread.join(5)
