"""A single-node Apache Kafka (KRaft: broker and controller in one JVM) on loopback."""

from __future__ import annotations

import base64
import subprocess
import uuid
from dataclasses import dataclass
from pathlib import Path

from fleetlink.localstack.errors import StackError
from fleetlink.localstack.process import ServerProcess, ensure_port_free, log_tail, port_in_use

_LOG4J2 = """status = warn
appender.console.type = Console
appender.console.name = STDOUT
appender.console.layout.type = PatternLayout
appender.console.layout.pattern = [%d] %p %m (%c)%n
rootLogger.level = info
rootLogger.appenderRef.stdout.ref = STDOUT
logger.kafka.name = kafka
logger.kafka.level = warn
logger.org.name = org.apache.kafka
logger.org.level = warn
logger.started.name = kafka.server.KafkaRaftServer
logger.started.level = info
"""

JVM_OPTS = ["-Xms256m", "-Xmx1g", "-XX:+UseG1GC", "-Djava.awt.headless=true"]


@dataclass(frozen=True)
class KafkaSettings:
    """Where the single-node broker listens and keeps its data, and its optional SASL listener."""

    port: int
    controller_port: int
    data_dir: Path
    advertised_port: int | None = None  # a relay in front of the broker (fault tests)
    host: str = "127.0.0.1"
    sasl_port: int | None = None
    """A second listener, SASL_PLAINTEXT with the PLAIN mechanism, for ``sasl_users``."""
    sasl_users: tuple[tuple[str, str], ...] = ()
    """(user, password) pairs the SASL listener accepts."""

    @property
    def bootstrap(self) -> str:
        """``host:port`` clients bootstrap from: the advertised port (a relay) when set, else the broker's."""
        return f"{self.host}:{self.advertised_port or self.port}"


def server_properties(s: KafkaSettings) -> str:
    """The broker's ``server.properties`` text for ``s``: one KRaft node, replication factor 1."""
    advertised = s.advertised_port or s.port
    props = {
        "process.roles": "broker,controller",
        "node.id": "1",
        "controller.quorum.bootstrap.servers": f"{s.host}:{s.controller_port}",
        "listeners": f"PLAINTEXT://{s.host}:{s.port},CONTROLLER://{s.host}:{s.controller_port}",
        "advertised.listeners": f"PLAINTEXT://{s.host}:{advertised}",
        "controller.listener.names": "CONTROLLER",
        "inter.broker.listener.name": "PLAINTEXT",
        "listener.security.protocol.map": "PLAINTEXT:PLAINTEXT,CONTROLLER:PLAINTEXT",
        "log.dirs": str(s.data_dir / "logs"),
        "num.partitions": "1",
        "offsets.topic.replication.factor": "1",
        "offsets.topic.num.partitions": "4",
        "transaction.state.log.replication.factor": "1",
        "transaction.state.log.min.isr": "1",
        "transaction.state.log.num.partitions": "4",
        "share.coordinator.state.topic.replication.factor": "1",
        "share.coordinator.state.topic.min.isr": "1",
        "group.initial.rebalance.delay.ms": "0",
        "auto.create.topics.enable": "true",
        "log.segment.bytes": str(64 * 1024 * 1024),
        # records carry their ROS source time; replayed bags are years old, and time-based
        # retention would delete them within minutes on this test/demo broker
        "log.retention.ms": "-1",
    }
    if s.sasl_port is not None:
        users = " ".join(f'user_{user}="{password}"' for user, password in s.sasl_users)
        props["listeners"] += f",SASL_PLAINTEXT://{s.host}:{s.sasl_port}"
        props["advertised.listeners"] += f",SASL_PLAINTEXT://{s.host}:{s.sasl_port}"
        props["listener.security.protocol.map"] += ",SASL_PLAINTEXT:SASL_PLAINTEXT"
        props["sasl.enabled.mechanisms"] = "PLAIN"
        props["listener.name.sasl_plaintext.plain.sasl.jaas.config"] = (
            f"org.apache.kafka.common.security.plain.PlainLoginModule required {users};"
        )
    return "".join(f"{k}={v}\n" for k, v in props.items())


class KafkaBroker:
    """Formats storage on first start, then runs ``kafka.Kafka server.properties``."""

    def __init__(self, settings: KafkaSettings, classpath: str, java: str) -> None:
        self.settings = settings
        self._classpath = classpath
        self._java = java
        data = settings.data_dir
        self._props = data / "server.properties"
        self._log4j = data / "log4j2.properties"
        self.process = ServerProcess(
            name=f"Kafka broker on {settings.host}:{settings.port}",
            argv=[
                java,
                *JVM_OPTS,
                f"-Dlog4j2.configurationFile={self._log4j}",
                "-cp",
                classpath,
                "kafka.Kafka",
                str(self._props),
            ],
            log_path=data / "kafka.log",
            pid_path=data / "kafka.pid",
            ready=self._ready,
        )

    @property
    def bootstrap(self) -> str:
        """``host:port`` clients bootstrap from (see ``KafkaSettings.bootstrap``)."""
        return self.settings.bootstrap

    def _ready(self) -> bool:
        if not port_in_use(self.settings.port, self.settings.host):
            return False
        from confluent_kafka import KafkaException
        from confluent_kafka.admin import AdminClient

        admin = AdminClient({"bootstrap.servers": f"{self.settings.host}:{self.settings.port}"})
        try:
            md = admin.list_topics(timeout=1.0)
        except KafkaException:  # not answering yet: keep polling until the deadline
            return False
        return bool(md.brokers)

    def _format(self) -> None:
        data = self.settings.data_dir
        data.mkdir(parents=True, exist_ok=True)
        self._props.write_text(server_properties(self.settings))
        self._log4j.write_text(_LOG4J2)
        if (data / "logs" / "meta.properties").exists():
            return
        cluster_id = base64.urlsafe_b64encode(uuid.uuid4().bytes).rstrip(b"=").decode()
        proc = subprocess.run(
            [
                self._java,
                f"-Dlog4j2.configurationFile={self._log4j}",
                "-cp",
                self._classpath,
                # "=": a generated id may start with "-", which would read as an option
                "kafka.tools.StorageTool",
                "format",
                "--standalone",
                f"--cluster-id={cluster_id}",
                "-c",
                str(self._props),
            ],
            capture_output=True,
            text=True,
            check=False,
        )
        if proc.returncode != 0:
            raise StackError(f"formatting Kafka storage in {data} failed:\n{proc.stdout}{proc.stderr}")

    def start(self, timeout: float = 90.0) -> float:
        """Check the ports are free, format storage on first use, and run the broker until it answers.

        Returns the seconds it took; raises ``StackError`` (with the log's last lines) when it does not
        come up within ``timeout`` seconds.
        """
        ensure_port_free(self.settings.port, "the Kafka broker", self.settings.host)
        if self.settings.sasl_port is not None:
            ensure_port_free(self.settings.sasl_port, "the Kafka broker's SASL listener", self.settings.host)
        ensure_port_free(self.settings.controller_port, "the Kafka controller", self.settings.host)
        self._format()
        return self.process.start(timeout)

    def stop(self) -> None:
        """Stop the broker: SIGTERM, then SIGKILL if it has not exited within 20 s."""
        self.process.stop()

    def log_tail(self) -> str:
        """The last lines of the broker's log, for error messages."""
        return log_tail(self.process.log_path)
