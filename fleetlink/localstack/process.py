"""Start a server process with its own log file, wait until it answers, stop it by PID."""

from __future__ import annotations

import contextlib
import os
import random
import signal
import socket
import subprocess
import threading
import time
from collections import deque
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path

from fleetlink.localstack.errors import StackError


def exit_on_sigterm() -> None:
    """Make SIGTERM end this process like Ctrl-C does: ``SystemExit(143)`` in the main thread,
    so ``with`` blocks and ``finally`` clauses stop what it started (Kafka, the registry, child
    processes) instead of leaving them running. For scripts; services handle SIGTERM themselves."""

    def handler(signum: int, _frame: object) -> None:
        raise SystemExit(128 + signum)

    signal.signal(signal.SIGTERM, handler)


_CLAIMS_KEPT = 512
"""Port claims a process holds (the oldest given back first)."""
_claims: deque[socket.socket] = deque()
_claims_lock = threading.Lock()


def free_port(host: str = "127.0.0.1") -> int:
    """A TCP port on ``host`` that is free now and that nothing else will be handed meanwhile.

    The port is told to a server that binds it seconds later, so two things must not take it in
    between. Outgoing connections: their source ports come from the kernel's ephemeral range
    (``net.ipv4.ip_local_port_range``), and the port is picked below it. Other processes picking
    ports this way (two test runs, a demo beside them): each port is claimed with an abstract
    Unix socket named for it, held by this process (its last ``_CLAIMS_KEPT`` ports); a port
    claimed elsewhere is passed over. Where neither works, the OS picks one (port 0)."""
    low, high = _below_ephemeral()
    for _attempt in range(256):
        port = random.randint(low, high)
        claim = _claim(port)
        if claim is None:
            continue
        if _bindable(host, port):
            with _claims_lock:
                _claims.append(claim)
                while len(_claims) > _CLAIMS_KEPT:
                    _claims.popleft().close()
            return port
        claim.close()
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind((host, 0))
        picked: int = s.getsockname()[1]
        return picked


def _below_ephemeral() -> tuple[int, int]:
    """The ports below the kernel's ephemeral range (at most 12,000 of them, none under 10,000)."""
    try:
        low = int(Path("/proc/sys/net/ipv4/ip_local_port_range").read_text().split()[0])
    except (OSError, ValueError, IndexError):
        low = 32768
    high = max(low - 1, 10_001)
    return max(10_000, high - 12_000), high


def _claim(port: int) -> socket.socket | None:
    """An abstract Unix socket named for ``port`` (machine-wide, gone with its process), or None
    when another process holds it or the platform has none."""
    claim = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    try:
        claim.bind(f"\0fleetlink-port-{port}")
    except OSError:
        claim.close()
        return None
    return claim


def _bindable(host: str, port: int) -> bool:
    """Whether a listener could bind ``host:port`` now (no listener, no lingering connection)."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        try:
            s.bind((host, port))
        except OSError:
            return False
        return True


def port_in_use(port: int, host: str = "127.0.0.1") -> bool:
    """Whether something accepts TCP connections on ``host:port`` (checked within 0.2 s)."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.settimeout(0.2)
        return s.connect_ex((host, port)) == 0


def ensure_port_free(port: int, what: str, host: str = "127.0.0.1") -> None:
    """Raise ``StackError`` naming ``what`` when ``host:port`` is already in use."""
    if port_in_use(port, host):
        raise StackError(
            f"port {host}:{port} for {what} is already in use; stop whatever listens there "
            f"(`ss -ltnp 'sport = :{port}'`) or choose another port"
        )


def log_tail(path: Path, lines: int = 30) -> str:
    """The last ``lines`` lines of the log at ``path`` (``(no log)`` when it cannot be read)."""
    try:
        text = path.read_text(encoding="utf-8", errors="replace")
    except OSError:
        return "(no log)"
    return "\n".join(text.splitlines()[-lines:])


@dataclass
class ServerProcess:
    """One server process: argv, log file, PID file; ``start`` returns once ``ready()`` is true."""

    name: str
    argv: Sequence[str]
    log_path: Path
    pid_path: Path
    ready: Callable[[], bool]
    env: dict[str, str] = field(default_factory=dict)
    cwd: Path | None = None
    _proc: subprocess.Popen[bytes] | None = None

    @property
    def pid(self) -> int | None:
        """The process's PID: the one started here, else the one in the PID file (None when neither)."""
        return self._proc.pid if self._proc else read_pid(self.pid_path)

    def start(self, timeout: float) -> float:
        """Start and wait until ready; returns the seconds it took. Raises with the log tail."""
        self.log_path.parent.mkdir(parents=True, exist_ok=True)
        began = time.monotonic()
        with self.log_path.open("ab") as log:
            self._proc = subprocess.Popen(
                list(self.argv),
                stdout=log,
                stderr=subprocess.STDOUT,
                stdin=subprocess.DEVNULL,
                env={**os.environ, **self.env},
                cwd=self.cwd,
                start_new_session=True,
            )
        self.pid_path.write_text(str(self._proc.pid))
        deadline = began + timeout
        while time.monotonic() < deadline:
            code = self._proc.poll()
            if code is not None:
                raise StackError(
                    f"{self.name} exited with code {code} while starting; last lines of "
                    f"{self.log_path}:\n{log_tail(self.log_path)}"
                )
            if self.ready():
                return time.monotonic() - began
            time.sleep(0.2)  # polling a starting JVM; bounded by the deadline above
        self.stop()
        raise StackError(
            f"{self.name} did not come up within {timeout:.0f} s; last lines of "
            f"{self.log_path}:\n{log_tail(self.log_path)}"
        )

    def stop(self, timeout: float = 20.0) -> None:
        """SIGTERM the process group, SIGKILL it after ``timeout`` seconds, and remove the PID file."""
        pid = self.pid
        if pid is None:
            return
        stop_pid(pid, timeout)
        if self._proc is not None:
            with contextlib.suppress(subprocess.TimeoutExpired):
                self._proc.wait(timeout=1)
            self._proc = None
        with contextlib.suppress(FileNotFoundError):
            self.pid_path.unlink()

    def kill(self) -> None:
        """SIGKILL, for fault tests (no clean shutdown)."""
        pid = self.pid
        if pid is not None:
            with contextlib.suppress(ProcessLookupError):
                os.killpg(pid, signal.SIGKILL)
            if self._proc is not None:
                self._proc.wait(timeout=10)
                self._proc = None

    def signal(self, sig: signal.Signals) -> None:
        """Send ``sig`` to the process group (nothing when there is no PID)."""
        pid = self.pid
        if pid is not None:
            os.killpg(pid, sig)


def read_pid(path: Path) -> int | None:
    """The PID written in ``path``, or None when it is missing or unreadable."""
    try:
        return int(path.read_text().strip())
    except (OSError, ValueError):
        return None


def alive(pid: int) -> bool:
    """Whether process ``pid`` exists (a zombie child of this process counts as gone)."""
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    # a zombie child still "exists"; treat it as gone
    try:
        waited, _ = os.waitpid(pid, os.WNOHANG)
    except ChildProcessError:
        return True
    return waited == 0


def stop_pid(pid: int, timeout: float = 20.0) -> None:
    """SIGTERM the process group, then SIGKILL after ``timeout``."""
    try:
        os.killpg(pid, signal.SIGTERM)
    except ProcessLookupError:
        return
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if not alive(pid):
            return
        time.sleep(0.1)  # waiting for a process to exit; bounded
    with contextlib.suppress(ProcessLookupError):
        os.killpg(pid, signal.SIGKILL)
