"""``free_port``: below the ephemeral range, never handed to two processes at once."""

from __future__ import annotations

import socket
import subprocess
import sys
from pathlib import Path

from fleetlink.localstack.process import free_port

ROOT = Path(__file__).resolve().parents[3]


def ephemeral_low() -> int:
    return int(Path("/proc/sys/net/ipv4/ip_local_port_range").read_text().split()[0])


def test_ports_come_from_below_the_ephemeral_range_and_are_bindable() -> None:
    ports = [free_port() for _ in range(200)]
    assert len(set(ports)) == len(ports)  # claimed: this process is not handed one twice
    assert all(10_000 <= p < ephemeral_low() for p in ports)
    for port in ports[:20]:
        with socket.socket() as s:
            s.bind(("127.0.0.1", port))


def test_a_port_another_process_holds_is_never_handed_out() -> None:
    script = (
        "import sys\n"
        "from fleetlink.localstack.process import free_port\n"
        "print(' '.join(str(free_port()) for _ in range(300)), flush=True)\n"
        "sys.stdin.read()\n"  # hold the claims until told to go
    )
    other = subprocess.Popen(
        [sys.executable, "-c", script], cwd=ROOT, stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True
    )
    try:
        assert other.stdout is not None
        theirs = {int(p) for p in other.stdout.readline().split()}
        assert len(theirs) == 300
        mine = {free_port() for _ in range(3000)}
        assert not mine & theirs
    finally:
        other.communicate("", timeout=30)
