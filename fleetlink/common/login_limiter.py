"""Failed logins cost time: after a few wrong credentials a client must wait, longer each time.

Per client (an address, or a fixed name where there is none): after ``free`` failures in a
row the client is locked out for ``lockout_s``, and each failure after doubles that, up to
``max_lockout_s``. While locked out, attempts are refused unchecked (HTTP 429 with
``Retry-After``), so guessing gets no faster by trying harder, and a right token guessed during a
lockout is not told apart from a wrong one. A success clears the client; a client quiet for
``forget_s`` is forgotten. Thread-safe; the clock is injected.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable
from dataclasses import dataclass


@dataclass
class _Client:
    failures: int = 0
    locked_until: float = 0.0
    last: float = 0.0


class LoginLimiter:
    """Locks a client out after ``free`` failed logins in a row, doubling the wait with each failure after."""

    def __init__(
        self,
        *,
        free: int = 5,
        lockout_s: float = 1.0,
        max_lockout_s: float = 300.0,
        forget_s: float = 900.0,
        max_clients: int = 10_000,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        self._free = free
        self._lockout = lockout_s
        self._max_lockout = max_lockout_s
        self._forget = forget_s
        self._max_clients = max_clients
        self._clock = clock
        self._clients: dict[str, _Client] = {}
        self._lock = threading.Lock()
        self.refused = 0
        """Attempts refused unchecked while their client was locked out."""
        self.failed = 0
        """Attempts checked and found wrong."""

    def retry_after(self, client: str) -> float:
        """Seconds ``client`` must still wait (0: it may try now). Counts a refused attempt."""
        now = self._clock()
        with self._lock:
            entry = self._clients.get(client)
            if entry is None or entry.locked_until <= now:
                return 0.0
            self.refused += 1
            return entry.locked_until - now

    def failure(self, client: str) -> None:
        """Count a wrong credential from ``client`` and lock it out once it has failed ``free`` times."""
        now = self._clock()
        with self._lock:
            self.failed += 1
            entry = self._clients.get(client)
            if entry is None or now - entry.last > self._forget:
                if len(self._clients) >= self._max_clients:
                    self._prune(now)
                entry = self._clients[client] = _Client()
            entry.failures += 1
            entry.last = now
            beyond = entry.failures - self._free + 1
            if beyond > 0:
                entry.locked_until = now + min(self._max_lockout, self._lockout * 2 ** min(beyond - 1, 30))

    def success(self, client: str) -> None:
        """Forget ``client``'s failures and lockout after a right credential."""
        with self._lock:
            self._clients.pop(client, None)

    def _prune(self, now: float) -> None:
        stale = [c for c, e in self._clients.items() if now - e.last > self._forget and e.locked_until <= now]
        for client in stale or list(self._clients)[: len(self._clients) // 2]:
            del self._clients[client]
