"""Kafka + schema registry together: start both (in parallel), report timings, stop both."""

from __future__ import annotations

import json
import logging
from concurrent.futures import ThreadPoolExecutor
from dataclasses import asdict, dataclass
from pathlib import Path

from fleetlink.common.lifecycle import StartStop
from fleetlink.localstack.artifacts import APICURIO_JAVA17_VERSION, APICURIO_VERSION, fetch_all
from fleetlink.localstack.errors import StackError
from fleetlink.localstack.java import KAFKA_MIN_JAVA, REGISTRY_MIN_JAVA, find_java
from fleetlink.localstack.kafka import KafkaBroker, KafkaSettings
from fleetlink.localstack.process import alive, free_port, read_pid, stop_pid
from fleetlink.localstack.registry import RegistrySettings, SchemaRegistry

log = logging.getLogger(__name__)

STATE_FILE = "stack.json"


@dataclass(frozen=True)
class StackInfo:
    """What a running stack is: written to <dir>/stack.json for `status`/`down` and for tests."""

    bootstrap: str
    registry_url: str
    kafka_pid: int
    registry_pid: int
    kafka_seconds: float
    registry_seconds: float

    def save(self, directory: Path) -> None:
        """Write the info to ``<directory>/stack.json``."""
        (directory / STATE_FILE).write_text(json.dumps(asdict(self), indent=2))

    @staticmethod
    def load(directory: Path) -> StackInfo | None:
        """The info in ``<directory>/stack.json``, or None when it is missing or unreadable."""
        try:
            return StackInfo(**json.loads((directory / STATE_FILE).read_text()))
        except (OSError, ValueError, TypeError):
            return None


class LocalStack(StartStop):
    """Real Kafka (KRaft) and Apicurio Registry as processes under ``directory``."""

    def __init__(
        self,
        directory: Path,
        *,
        kafka_port: int | None = None,
        registry_port: int | None = None,
        kafka_advertised_port: int | None = None,
    ) -> None:
        self.directory = directory
        self._kafka_port = kafka_port
        self._registry_port = registry_port
        self._advertised = kafka_advertised_port
        self.kafka: KafkaBroker | None = None
        self.registry: SchemaRegistry | None = None
        self.info: StackInfo | None = None

    def start(self, kafka_timeout: float = 90.0, registry_timeout: float = 120.0) -> StackInfo:
        """Fetch what is missing, start Kafka and the registry in parallel and record them in ``stack.json``.

        Picks free ports for those not given, and Apicurio Registry's Java 17 line when no Java 21 is
        found. Raises ``StackError`` (after stopping both) when either does not come up in time.
        """
        kafka_java = find_java(KAFKA_MIN_JAVA, "Apache Kafka 4")
        try:
            registry_java = find_java(REGISTRY_MIN_JAVA, "Apicurio Registry")
            registry_version = APICURIO_VERSION
        except StackError:
            # no Java 21 here: the 3.0 line of the same registry runs on Java 17
            registry_java, registry_version = kafka_java, APICURIO_JAVA17_VERSION
            log.info(
                "no Java %d+; using Apicurio Registry %s on Java 17", REGISTRY_MIN_JAVA, registry_version
            )
        artifacts = fetch_all(apicurio_version=registry_version)
        self.directory.mkdir(parents=True, exist_ok=True)
        self.kafka = KafkaBroker(
            KafkaSettings(
                port=self._kafka_port or free_port(),
                controller_port=free_port(),
                data_dir=self.directory / "kafka",
                advertised_port=self._advertised,
            ),
            artifacts.kafka_classpath,
            kafka_java,
        )
        self.registry = SchemaRegistry(
            RegistrySettings(port=self._registry_port or free_port(), data_dir=self.directory / "registry"),
            artifacts.apicurio_jar,
            registry_java,
        )
        with ThreadPoolExecutor(max_workers=2) as pool:
            kafka_job = pool.submit(self.kafka.start, kafka_timeout)
            registry_job = pool.submit(self.registry.start, registry_timeout)
            errors = []
            for job in (kafka_job, registry_job):
                exc = job.exception()
                if exc is not None:
                    errors.append(exc)
        if errors:
            self.stop()
            raise StackError("; ".join(str(e) for e in errors))
        kafka_pid, registry_pid = self.kafka.process.pid, self.registry.process.pid
        if kafka_pid is None or registry_pid is None:
            raise StackError("a service started but left no PID; see the logs under " + str(self.directory))
        self.info = StackInfo(
            bootstrap=self.kafka.bootstrap,
            registry_url=self.registry.url,
            kafka_pid=kafka_pid,
            registry_pid=registry_pid,
            kafka_seconds=round(kafka_job.result(), 2),
            registry_seconds=round(registry_job.result(), 2),
        )
        self.info.save(self.directory)
        return self.info

    def stop(self) -> None:
        """Stop the registry and Kafka if they were started, and remove ``stack.json``."""
        for server in (self.registry, self.kafka):
            if server is not None:
                server.stop()
        (self.directory / STATE_FILE).unlink(missing_ok=True)


def stop_recorded(directory: Path) -> bool:
    """Stop a stack started by another process (``fleetlink stack down``). True if one was running."""
    info = StackInfo.load(directory)
    pids = [read_pid(directory / "kafka" / "kafka.pid"), read_pid(directory / "registry" / "registry.pid")]
    if info is not None:
        pids += [info.kafka_pid, info.registry_pid]
    stopped = False
    for pid in {p for p in pids if p is not None}:
        if alive(pid):
            stop_pid(pid)
            stopped = True
    (directory / STATE_FILE).unlink(missing_ok=True)
    return stopped
