"""Fetch the Kafka broker jars and the Apicurio Registry distribution from Maven Central, once.

The first run shows what it downloads (files and megabytes, every few seconds). A lock file in
the cache folder lets one process fetch at a time: a second one waits, then finds the jars there.
"""

from __future__ import annotations

import collections
import contextlib
import fcntl
import functools
import logging
import os
import re
import shutil
import subprocess
import tarfile
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path

from fleetlink.localstack.errors import StackError

log = logging.getLogger(__name__)

KAFKA_VERSION = "4.2.1"
LOG4J_VERSION = "2.25.3"
APICURIO_VERSION = "3.3.3"  # needs Java 21+
APICURIO_JAVA17_VERSION = "3.0.9"  # the newest 3.x line that still runs on Java 17
S3PROXY_VERSION = "4.1.0"  # S3 API over a local folder; Java 17 class files

_KAFKA_POM = """<project xmlns="http://maven.apache.org/POM/4.0.0">
  <modelVersion>4.0.0</modelVersion>
  <groupId>fleetlink.localstack</groupId>
  <artifactId>kafka-broker</artifactId>
  <version>1</version>
  <packaging>pom</packaging>
  <dependencies>
    <dependency><groupId>org.apache.kafka</groupId><artifactId>kafka_2.13</artifactId>
      <version>{kafka}</version></dependency>
    <dependency><groupId>org.apache.logging.log4j</groupId><artifactId>log4j-core</artifactId>
      <version>{log4j}</version></dependency>
    <dependency><groupId>org.apache.logging.log4j</groupId><artifactId>log4j-slf4j-impl</artifactId>
      <version>{log4j}</version></dependency>
  </dependencies>
</project>
"""


def cache_root() -> Path:
    """Where jars are kept between runs: $FLEETLINK_CACHE, else <project>/.cache."""
    env = os.environ.get("FLEETLINK_CACHE")
    if env:
        return Path(env).expanduser().resolve()
    return Path(__file__).resolve().parents[2] / ".cache"


@dataclass(frozen=True)
class Artifacts:
    """What the local stack runs: the Kafka broker's classpath and the Apicurio Registry jar."""

    kafka_classpath: str
    apicurio_jar: Path


def _mvn() -> str:
    mvn = shutil.which("mvn")
    if mvn is None:
        raise StackError(
            "Maven (mvn) is needed once to fetch the Kafka and Apicurio jars from Maven Central; "
            "install it (Debian: apt-get install maven) or set FLEETLINK_CACHE to a folder that "
            "already holds them"
        )
    return mvn


_DOWNLOADED = re.compile(r"^\[INFO\] Downloaded from \S+: \S+ \((?P<size>[\d.,]+) (?P<unit>[kMG]?B)")
_UNITS = {"B": 1, "kB": 1_000, "MB": 1_000_000, "GB": 1_000_000_000}


def downloaded_bytes(line: str) -> int | None:
    """The size of a file Maven reports it downloaded (``Downloaded from central: URL (1.2 MB at …)``)."""
    match = _DOWNLOADED.match(line.strip())
    if match is None:
        return None
    return int(float(match.group("size").replace(",", "")) * _UNITS[match.group("unit")])


class Progress:
    """Files and bytes fetched so far, told at most every ``every_s`` seconds (clock injected)."""

    def __init__(
        self, what: str, out: Callable[[str], None], clock: Callable[[], float], every_s: float = 2.0
    ):
        self.what = what
        self.out = out
        self.clock = clock
        self.every_s = every_s
        self.files = 0
        self.bytes = 0
        self._told_at = clock()

    def line(self, text: str) -> None:
        """Take one line of Maven's output, counting the file it reports downloaded (if any)."""
        size = downloaded_bytes(text)
        if size is None:
            return
        self.files += 1
        self.bytes += size
        if self.clock() - self._told_at >= self.every_s:
            self.tell()

    def tell(self) -> None:
        """Print the files and megabytes fetched so far."""
        self._told_at = self.clock()
        self.out(f"  {self.what}: {self.files} files, {self.bytes / 1e6:.1f} MB so far")

    def done(self) -> None:
        """Print the totals downloaded, or that Maven's local repository already had everything."""
        if self.files:
            self.out(f"  {self.what}: {self.files} files, {self.bytes / 1e6:.1f} MB downloaded")
        else:
            self.out(f"  {self.what}: nothing to download (Maven's local repository had it)")


def _run_mvn(args: list[str], cwd: Path, what: str) -> None:
    log.info("fetching %s from Maven Central (first run only)", what)
    say = functools.partial(print, flush=True)
    say(f"fleetlink stack: fetching {what} from Maven Central (first run only; cached in {cwd})")
    progress = Progress(what, say, time.monotonic)
    tail: collections.deque[str] = collections.deque(maxlen=20)
    with subprocess.Popen(
        [_mvn(), "-B", *args],
        cwd=cwd,
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
    ) as proc:
        assert proc.stdout is not None
        for line in proc.stdout:
            tail.append(line.rstrip())
            progress.line(line)
        code = proc.wait()
    if code != 0:
        raise StackError(f"could not fetch {what} with Maven (exit {code}):\n" + "\n".join(tail))
    progress.done()


@contextlib.contextmanager
def cache_lock(root: Path) -> Iterator[None]:
    """One fetch at a time per cache folder, across processes (``flock`` on ``<root>/.fetch.lock``):
    two first runs at once would otherwise download into, and rename, the same folders."""
    root.mkdir(parents=True, exist_ok=True)
    with (root / ".fetch.lock").open("a") as handle:
        try:
            fcntl.flock(handle, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            print(f"fleetlink stack: waiting for another process fetching into {root} ...", flush=True)
            fcntl.flock(handle, fcntl.LOCK_EX)
        try:
            yield
        finally:
            fcntl.flock(handle, fcntl.LOCK_UN)


def fetch_kafka(root: Path) -> Path:
    """Fetch the Kafka broker jars with Maven unless cached; returns the folder holding them."""
    lib = root / f"kafka-{KAFKA_VERSION}" / "lib"
    done = lib / ".complete"
    if done.exists():
        return lib
    with cache_lock(root):
        if done.exists():  # fetched by another process while this one waited
            return lib
        work = lib.parent
        work.mkdir(parents=True, exist_ok=True)
        (work / "pom.xml").write_text(_KAFKA_POM.format(kafka=KAFKA_VERSION, log4j=LOG4J_VERSION))
        tmp = work / "lib.partial"
        shutil.rmtree(tmp, ignore_errors=True)
        _run_mvn(
            ["dependency:copy-dependencies", f"-DoutputDirectory={tmp}", "-DincludeScope=runtime"],
            work,
            f"Apache Kafka {KAFKA_VERSION} broker jars",
        )
        shutil.rmtree(lib, ignore_errors=True)
        tmp.rename(lib)
        done.touch()
    return lib


def fetch_apicurio(root: Path, version: str = APICURIO_VERSION) -> Path:
    """Fetch and unpack the registry distribution; returns the jar to run with ``java -jar``."""
    home = root / f"apicurio-registry-{version}"
    done = home / ".complete"
    if done.exists():
        return _apicurio_jar(home)
    with cache_lock(root):
        if not done.exists():  # else fetched by another process while this one waited
            _fetch_apicurio(home, version)
            done.touch()
    return _apicurio_jar(home)


def _fetch_apicurio(home: Path, version: str) -> None:
    shutil.rmtree(home, ignore_errors=True)  # what an interrupted fetch left
    home.mkdir(parents=True)
    artifact = f"io.apicurio:apicurio-registry-app:{version}:tar.gz:all"
    _run_mvn(
        ["dependency:copy", f"-Dartifact={artifact}", f"-DoutputDirectory={home}"],
        home,
        f"Apicurio Registry {version}",
    )
    archives = sorted(home.glob("*.tar.gz"))
    if not archives:
        raise StackError(f"Maven reported success but no Apicurio archive is in {home}")
    with tarfile.open(archives[0]) as tar:
        tar.extractall(home / "dist", filter="data")
    archives[0].unlink()


def _apicurio_jar(home: Path) -> Path:
    # 3.3+ ships a Quarkus fast-jar (quarkus-run.jar); 3.0 an uber "-runner.jar"
    dist = home / "dist"
    runners = sorted(dist.rglob("quarkus-run.jar")) or sorted(dist.rglob("*-runner.jar"))
    if not runners:
        raise StackError(f"no runnable jar under {home / 'dist'}; delete {home} and fetch again")
    return runners[0]


def fetch_s3proxy(root: Path | None = None, version: str = S3PROXY_VERSION) -> Path:
    """Fetch s3proxy's runnable jar (``org.gaul:s3proxy``, classifier jar-with-dependencies)."""
    root = root or cache_root()
    home = root / f"s3proxy-{version}"
    jar = home / f"s3proxy-{version}-jar-with-dependencies.jar"
    done = home / ".complete"
    if done.exists() and jar.exists():
        return jar
    with cache_lock(root):
        if done.exists() and jar.exists():  # fetched by another process while this one waited
            return jar
        shutil.rmtree(home, ignore_errors=True)  # what an interrupted fetch left
        home.mkdir(parents=True)
        _run_mvn(
            [
                "dependency:copy",
                f"-Dartifact=org.gaul:s3proxy:{version}:jar:jar-with-dependencies",
                f"-DoutputDirectory={home}",
            ],
            home,
            f"s3proxy {version}",
        )
        if not jar.exists():
            raise StackError(f"Maven reported success but {jar.name} is not in {home}")
        done.touch()
    return jar


def fetch_all(root: Path | None = None, apicurio_version: str = APICURIO_VERSION) -> Artifacts:
    """Fetch (unless cached) the Kafka broker jars and Apicurio Registry ``apicurio_version``."""
    root = root or cache_root()
    lib = fetch_kafka(root)
    classpath = os.pathsep.join(str(p) for p in sorted(lib.glob("*.jar")))
    return Artifacts(kafka_classpath=classpath, apicurio_jar=fetch_apicurio(root, apicurio_version))
