"""Find a Java runtime new enough for Kafka 4 (Java 17+), or say plainly what is missing."""

from __future__ import annotations

import os
import re
import shutil
import subprocess
from pathlib import Path

from fleetlink.localstack.errors import StackError

KAFKA_MIN_JAVA = 17  # Apache Kafka 4.x brokers
REGISTRY_MIN_JAVA = 21  # Apicurio Registry 3.3 (Quarkus, class file version 65)
JVM_ROOT = Path("/usr/lib/jvm")


def _candidates() -> list[str]:
    found: list[str] = []
    home = os.environ.get("JAVA_HOME")
    if home:
        found.append(str(Path(home) / "bin" / "java"))
    on_path = shutil.which("java")
    if on_path:
        found.append(on_path)
    if JVM_ROOT.is_dir():
        found.extend(str(p / "bin" / "java") for p in sorted(JVM_ROOT.iterdir()))
    return [c for i, c in enumerate(found) if Path(c).exists() and c not in found[:i]]


def find_java(minimum: int = KAFKA_MIN_JAVA, purpose: str = "Kafka") -> str:
    """The first Java at least ``minimum``: $JAVA_HOME, then PATH, then /usr/lib/jvm/*."""
    seen: list[str] = []
    for candidate in _candidates():
        try:
            version = java_major_version(candidate)
        except StackError:
            continue
        if version >= minimum:
            return candidate
        seen.append(f"{candidate} (Java {version})")
    have = "; found only " + ", ".join(seen) if seen else "; no `java` was found"
    raise StackError(
        f"{purpose} needs Java {minimum} or newer{have}. Install one (e.g. Debian: apt-get install "
        f"openjdk-{max(minimum, 17)}-jre-headless, or a Temurin JDK) or set JAVA_HOME to it"
    )


def java_major_version(java: str) -> int:
    """The major version ``java -version`` reports (8 for ``1.8.0``); ``StackError`` when unclear."""
    proc = subprocess.run([java, "-version"], capture_output=True, text=True, check=False)
    text = proc.stderr + proc.stdout
    match = re.search(r'version "(\d+)(?:\.(\d+))?', text)
    if not match:
        raise StackError(f"cannot tell the version of {java}: {text.strip()[:200]}")
    major = int(match.group(1))
    if major == 1 and match.group(2):  # "1.8.0" style
        major = int(match.group(2))
    return major
