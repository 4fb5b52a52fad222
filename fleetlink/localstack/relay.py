"""A TCP relay the tests control: pass, blackhole (hang-style), delay, refuse, reset; counts bytes.

Placed between two Zenoh routers (the WAN link) or between clients and Kafka, it injects the
faults of docs/reliability.md and counts the bytes that really cross the link. It runs an
asyncio loop in a daemon thread; every public method is thread-safe.

- ``pass``: bytes flow both ways.
- ``blackhole``: connections stay open but bytes are silently dropped (a hung WAN: no RST,
  no FIN), and new connections are accepted and then starved the same way.
- ``delay``: each chunk is forwarded after ``delay_s``.
- ``refuse``: a service that is down: open connections are reset and new ones are aborted as
  soon as they are accepted (the client sees a reset, at once).
- ``reset()``: every open connection is aborted with RST (new ones are accepted as usual).
"""

from __future__ import annotations

import asyncio
import contextlib
import socket
import struct
import threading
from dataclasses import dataclass
from typing import Literal

Mode = Literal["pass", "blackhole", "delay", "refuse"]


@dataclass
class RelayCounters:
    """What crossed the relay: bytes each way, connections accepted and connections aborted with RST."""

    upstream_bytes: int = 0  # client → target
    downstream_bytes: int = 0  # target → client
    connections: int = 0
    resets: int = 0

    @property
    def total_bytes(self) -> int:
        """Bytes forwarded in both directions."""
        return self.upstream_bytes + self.downstream_bytes


class TcpRelay:
    """A TCP relay from ``host:port`` to ``host:target_port`` whose faults tests switch at runtime."""

    def __init__(self, target_port: int, *, listen_port: int = 0, host: str = "127.0.0.1") -> None:
        self.host = host
        self.target_port = target_port
        self._listen_port = listen_port
        self.mode: Mode = "pass"
        self.delay_s = 0.0
        self.counters = RelayCounters()
        self._lock = threading.Lock()
        self._loop: asyncio.AbstractEventLoop | None = None
        self._thread: threading.Thread | None = None
        self._server: asyncio.base_events.Server | None = None
        self._writers: set[asyncio.StreamWriter] = set()
        self._ready = threading.Event()

    @property
    def port(self) -> int:
        """The port the relay listens on (the one picked at start when ``listen_port`` was 0)."""
        return self._listen_port

    @property
    def endpoint(self) -> str:
        """The relay as a Zenoh endpoint, ``tcp/host:port``."""
        return f"tcp/{self.host}:{self.port}"

    def start(self) -> TcpRelay:
        """Start the relay's loop thread and wait until it listens; returns ``self``.

        Raises ``RuntimeError`` when it does not listen within 10 s.
        """
        self._thread = threading.Thread(target=self._run, name=f"relay:{self.target_port}", daemon=True)
        self._thread.start()
        if not self._ready.wait(10):
            raise RuntimeError("relay did not start")
        return self

    def stop(self) -> None:
        """Stop listening, abort every open connection and end the loop thread (no-op when stopped)."""
        loop = self._loop
        if loop is None:
            return
        fut = asyncio.run_coroutine_threadsafe(self._shutdown(), loop)
        with contextlib.suppress(Exception):
            fut.result(10)
        loop.call_soon_threadsafe(loop.stop)
        if self._thread is not None:
            self._thread.join(10)
        self._loop = None

    def __enter__(self) -> TcpRelay:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()

    def set_mode(self, mode: Mode, delay_s: float = 0.0) -> None:
        """Switch to ``mode`` (``delay_s``: the delay per chunk in ``delay`` mode); ``refuse`` also resets."""
        with self._lock:
            self.mode = mode
            self.delay_s = delay_s
        if mode == "refuse":
            self.reset()

    def reset(self) -> None:
        """Abort every open connection with RST."""
        loop = self._loop
        if loop is None:
            return
        asyncio.run_coroutine_threadsafe(self._reset_all(), loop).result(10)

    # -- loop side ---------------------------------------------------------------------------

    def _run(self) -> None:
        loop = asyncio.new_event_loop()
        self._loop = loop
        asyncio.set_event_loop(loop)
        self._server = loop.run_until_complete(
            asyncio.start_server(self._handle, self.host, self._listen_port)
        )
        self._listen_port = self._server.sockets[0].getsockname()[1]
        self._ready.set()
        loop.run_forever()
        loop.close()

    async def _shutdown(self) -> None:
        if self._server is not None:
            self._server.close()
        await self._reset_all()

    async def _reset_all(self) -> None:
        for writer in list(self._writers):
            self._abort(writer)
        self._writers.clear()

    def _abort(self, writer: asyncio.StreamWriter) -> None:
        """Close with RST (SO_LINGER 0), not FIN."""
        sock = writer.get_extra_info("socket")
        if sock is not None:
            with contextlib.suppress(OSError):
                sock.setsockopt(socket.SOL_SOCKET, socket.SO_LINGER, struct.pack("ii", 1, 0))
        writer.transport.abort()
        with self._lock:
            self.counters.resets += 1

    async def _handle(self, client_r: asyncio.StreamReader, client_w: asyncio.StreamWriter) -> None:
        with self._lock:
            self.counters.connections += 1
            refuse = self.mode == "refuse"
        if refuse:
            self._abort(client_w)
            return
        try:
            target_r, target_w = await asyncio.open_connection(self.host, self.target_port)
        except OSError:
            client_w.transport.abort()
            return
        self._writers.update((client_w, target_w))
        await asyncio.gather(
            self._pipe(client_r, target_w, upstream=True),
            self._pipe(target_r, client_w, upstream=False),
            return_exceptions=True,
        )
        for w in (client_w, target_w):
            self._writers.discard(w)
            w.transport.abort()

    async def _pipe(
        self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter, *, upstream: bool
    ) -> None:
        while True:
            chunk = await reader.read(65536)
            if not chunk:
                writer.transport.abort()
                return
            with self._lock:
                mode, delay = self.mode, self.delay_s
            if mode == "blackhole":
                continue  # swallowed: the peer sees a hung link
            if mode == "delay" and delay > 0:
                await asyncio.sleep(delay)
            with self._lock:
                if upstream:
                    self.counters.upstream_bytes += len(chunk)
                else:
                    self.counters.downstream_bytes += len(chunk)
            writer.write(chunk)
            await writer.drain()
