"""The fault-detection app in Java (``examples/kafka-streams-fault-detection/``), seen from Python.

Where its Maven project is, how to build it (``mvn -q -B package``), the command line that runs
the jar, and what its log lines mean. The demo (``fleetlink demo --app java``) and the tests use
this; the app itself is a plain Kafka Streams application (docs/guides/stream-developer-java.md).
"""

from __future__ import annotations

import re
import shutil
import subprocess
import time
from dataclasses import dataclass
from pathlib import Path

from fleetlink.common.errors import FleetlinkError

__all__ = [
    "JAR",
    "PROJECT",
    "JavaAppError",
    "StateChange",
    "build",
    "command",
    "needs_build",
    "parse_state_change",
]

PROJECT = Path(__file__).resolve().parent / "kafka-streams-fault-detection"
JAR = PROJECT / "target" / "kafka-streams-fault-detection.jar"
READY_LINE = "running: application.id="
"""The app logs this once Kafka Streams is RUNNING (partitions assigned, state restored)."""

_STATE_CHANGE = re.compile(
    r"robot=(?P<robot>\S+) state=(?P<before>\w+)->(?P<after>\w+) window_end_ms=(?P<end>-?\d+)"
    r".* command_id=(?P<id>\S+)"
)


class JavaAppError(FleetlinkError):
    """The Java app could not be built (no Maven, a failed build) or found."""


@dataclass(frozen=True)
class StateChange:
    """One decision the app logged: ``robot`` moved from ``before`` to ``after`` at ``window_end_ms``."""

    robot: str
    before: str
    after: str
    window_end_ms: int
    command_id: str


def parse_state_change(line: str) -> StateChange | None:
    """The state change a log line of the app reports, or None for any other line."""
    match = _STATE_CHANGE.search(line)
    if match is None:
        return None
    return StateChange(match["robot"], match["before"], match["after"], int(match["end"]), match["id"])


def _sources() -> list[Path]:
    return [PROJECT / "pom.xml", *(p for p in (PROJECT / "src").rglob("*") if p.is_file())]


def needs_build() -> bool:
    """Whether the jar is missing or older than a source (pom, Java code, Avro schemas)."""
    if not JAR.exists():
        return True
    built = JAR.stat().st_mtime
    return any(p.stat().st_mtime > built for p in _sources())


def build(*, timeout_s: float = 1800.0, tests: bool = True) -> float:
    """``mvn -q -B package`` in the project; returns the seconds it took. Raises with Maven's output.

    The first build on a machine downloads the dependencies from Maven Central into ``~/.m2``;
    later ones need no network (every version is pinned).
    """
    mvn = shutil.which("mvn")
    if mvn is None:
        raise JavaAppError(
            "Maven (mvn) is needed to build the Kafka Streams app; install it (Debian: apt-get install maven)"
        )
    if not PROJECT.is_dir():
        raise JavaAppError(f"the Maven project is not here: {PROJECT} (it ships with the repository)")
    argv = [mvn, "-q", "-B", "-Dstyle.color=never", "package"]
    if not tests:
        argv.append("-DskipTests")
    began = time.monotonic()
    try:
        proc = subprocess.run(
            argv, cwd=PROJECT, capture_output=True, text=True, timeout=timeout_s, check=False
        )
    except subprocess.TimeoutExpired as exc:
        raise JavaAppError(f"`mvn package` in {PROJECT} took longer than {timeout_s:.0f} s") from exc
    if proc.returncode != 0 or not JAR.exists():
        output = (proc.stdout + proc.stderr).strip().splitlines()
        tail = "\n".join(output[-40:])
        raise JavaAppError(f"`mvn package` in {PROJECT} failed (exit {proc.returncode}):\n{tail}")
    return time.monotonic() - began


def command(
    java: str,
    *,
    bootstrap: str,
    registry_native_url: str,
    window_ms: int,
    group: str,
    state_dir: Path,
    from_beginning: bool = False,
    extra: tuple[str, ...] = (),
) -> list[str]:
    """The argv that runs the jar; ``registry_native_url``: Apicurio's native API, …/apis/registry/v3."""
    argv = [
        java,
        "-Xms64m",
        "-Xmx256m",
        "-jar",
        str(JAR),
        "--bootstrap",
        bootstrap,
        "--registry",
        registry_native_url,
        "--window",
        f"{window_ms}ms",
        "--group",
        group,
        "--state-dir",
        str(state_dir),
    ]
    if from_beginning:
        argv.append("--from-beginning")
    return [*argv, *extra]
