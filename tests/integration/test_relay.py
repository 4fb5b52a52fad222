"""The TCP relay used by fault tests: pass, blackhole, delay, reset, byte counts."""

from __future__ import annotations

import contextlib
import socket
import threading
from collections.abc import Iterator

import pytest

from fleetlink.localstack.relay import TcpRelay


@pytest.fixture
def echo_port() -> Iterator[int]:
    srv = socket.socket()
    srv.bind(("127.0.0.1", 0))
    srv.listen()
    stop = threading.Event()

    def serve() -> None:
        while not stop.is_set():
            try:
                conn, _ = srv.accept()
            except OSError:
                return
            threading.Thread(target=_echo, args=(conn,), daemon=True).start()

    threading.Thread(target=serve, daemon=True).start()
    yield srv.getsockname()[1]
    stop.set()
    srv.close()


def _echo(conn: socket.socket) -> None:
    with conn, contextlib.suppress(OSError):  # the relay aborts connections on purpose
        while data := conn.recv(65536):
            conn.sendall(data)


def _roundtrip(port: int, payload: bytes, timeout: float = 2.0) -> bytes:
    with socket.create_connection(("127.0.0.1", port), timeout=timeout) as s:
        s.sendall(payload)
        got = b""
        while len(got) < len(payload):
            chunk = s.recv(65536)
            if not chunk:
                break
            got += chunk
        return got


def test_pass_forwards_and_counts(echo_port: int) -> None:
    with TcpRelay(echo_port) as relay:
        assert _roundtrip(relay.port, b"hello wan") == b"hello wan"
        assert relay.counters.upstream_bytes == 9
        assert relay.counters.downstream_bytes == 9


def test_blackhole_hangs_without_closing(echo_port: int) -> None:
    with TcpRelay(echo_port) as relay:
        relay.set_mode("blackhole")
        with pytest.raises(TimeoutError):
            _roundtrip(relay.port, b"lost", timeout=0.5)
        relay.set_mode("pass")
        assert _roundtrip(relay.port, b"healed") == b"healed"


def test_reset_aborts_open_connections(echo_port: int) -> None:
    with TcpRelay(echo_port) as relay, socket.create_connection(("127.0.0.1", relay.port), timeout=2) as s:
        s.sendall(b"x")
        assert s.recv(1) == b"x"
        relay.reset()
        with pytest.raises((ConnectionResetError, BrokenPipeError)):
            _write_until_broken(s)
        assert relay.counters.resets >= 1


def test_refuse_resets_open_connections_and_new_ones_until_passing_again(echo_port: int) -> None:
    with TcpRelay(echo_port) as relay, socket.create_connection(("127.0.0.1", relay.port), timeout=2) as s:
        s.sendall(b"x")
        assert s.recv(1) == b"x"
        relay.set_mode("refuse")
        with pytest.raises((ConnectionResetError, BrokenPipeError)):
            _write_until_broken(s)
        with pytest.raises((ConnectionResetError, BrokenPipeError)):
            _roundtrip(relay.port, b"anyone there?")
        relay.set_mode("pass")
        assert _roundtrip(relay.port, b"back") == b"back"


def _write_until_broken(s: socket.socket) -> None:
    for _ in range(50):
        s.sendall(b"y" * 1024)
        if not s.recv(1):
            raise ConnectionResetError
