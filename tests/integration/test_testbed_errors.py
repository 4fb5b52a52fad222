"""Bad set-up gets a clear message: port in use, a server that never becomes ready."""

from __future__ import annotations

import socket
import sys
from pathlib import Path

import pytest

from fleetlink.localstack.errors import StackError
from fleetlink.localstack.process import ServerProcess, ensure_port_free

STUCK = "import time; print('booting slowly', flush=True); time.sleep(60)"  # ok-sleep: stuck child


def test_port_in_use_is_reported_with_the_port() -> None:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        s.listen()
        port = s.getsockname()[1]
        expected = rf"port 127.0.0.1:{port} for the Kafka broker is already in use"
        with pytest.raises(StackError, match=expected):
            ensure_port_free(port, "the Kafka broker")


def test_server_not_ready_within_deadline_shows_log_tail(tmp_path: Path) -> None:
    server = ServerProcess(
        name="stuck server",
        # a deliberately stuck child process:
        argv=[sys.executable, "-c", STUCK],
        log_path=tmp_path / "stuck.log",
        pid_path=tmp_path / "stuck.pid",
        ready=lambda: False,
    )
    with pytest.raises(StackError, match=r"(?s)did not come up within 1 s.*booting slowly"):
        server.start(timeout=1.0)
    assert server.pid is None  # stopped, PID file removed


def test_server_that_exits_while_starting_shows_its_exit_code(tmp_path: Path) -> None:
    server = ServerProcess(
        name="crashing server",
        argv=[sys.executable, "-c", "import sys; print('bad config line 3'); sys.exit(7)"],
        log_path=tmp_path / "crash.log",
        pid_path=tmp_path / "crash.pid",
        ready=lambda: False,
    )
    with pytest.raises(StackError, match=r"(?s)exited with code 7.*bad config line 3"):
        server.start(timeout=30.0)
