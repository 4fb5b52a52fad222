"""Apicurio Registry 3 with its Confluent-compatible API, on loopback.

Its schemas are kept in an H2 database file in the data folder, next to Kafka's: a stack
restarted on the same folder (``fleetlink stack up --dir``) finds the schema ids its records
refer to.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import httpx

from fleetlink.localstack.process import ServerProcess, ensure_port_free, free_port, log_tail
from fleetlink.schemas.registry_urls import APICURIO_CCOMPAT_PATH, APICURIO_NATIVE_PATH, apicurio_native_url


@dataclass(frozen=True)
class RegistrySettings:
    """Where Apicurio Registry listens (HTTP and management ports) and keeps its schema database."""

    port: int
    data_dir: Path
    host: str = "127.0.0.1"
    management_port: int | None = None

    @property
    def url(self) -> str:
        """The URL Confluent clients take (``schema.registry.url``): fleetlink, confluent-kafka, Quix."""
        return f"http://{self.host}:{self.port}{APICURIO_CCOMPAT_PATH}"

    @property
    def native_url(self) -> str:
        """The registry's own API, which Apicurio's Java serdes take (``apicurio.registry.url``)."""
        return f"http://{self.host}:{self.port}{APICURIO_NATIVE_PATH}"


class SchemaRegistry:
    """Apicurio Registry as a process, its schemas in an H2 file under the data folder."""

    def __init__(self, settings: RegistrySettings, jar: Path, java: str) -> None:
        self.settings = settings
        data = settings.data_dir
        self.process = ServerProcess(
            name=f"Apicurio Registry on {settings.host}:{settings.port}",
            argv=[
                java,
                "-Xms128m",
                "-Xmx768m",
                f"-Dquarkus.http.host={settings.host}",
                f"-Dquarkus.http.port={settings.port}",
                # Quarkus' management interface (health, metrics) would take 0.0.0.0:9000
                f"-Dquarkus.management.host={settings.host}",
                f"-Dquarkus.management.port={settings.management_port or free_port()}",
                "-Dapicurio.storage.kind=sql",
                "-Dapicurio.storage.sql.kind=h2",
                # schemas in a file beside Kafka's data: ids outlive a restart, as the records do
                f"-Dapicurio.datasource.url=jdbc:h2:file:{(data / 'registry-db').absolute()}",
                "-Dquarkus.log.level=WARN",
                '-Dquarkus.log.category."io.quarkus".level=INFO',
                "-Dquarkus.http.limits.max-body-size=16M",
                "-jar",
                str(jar),
            ],
            log_path=data / "registry.log",
            pid_path=data / "registry.pid",
            ready=self._ready,
            cwd=jar.parent,
        )

    @property
    def url(self) -> str:
        """The Confluent-compatible URL clients take (``schema.registry.url``)."""
        return self.settings.url

    def _ready(self) -> bool:
        try:
            resp = httpx.get(f"{self.url}/subjects", timeout=1.0)
        except httpx.HTTPError:
            return False
        return resp.status_code == 200

    def start(self, timeout: float = 120.0) -> float:
        """Check the port is free and run the registry until it answers; returns the seconds it took.

        Raises ``StackError`` (with the log's last lines) when it does not answer within ``timeout``.
        """
        ensure_port_free(self.settings.port, "the schema registry", self.settings.host)
        self.settings.data_dir.mkdir(parents=True, exist_ok=True)
        return self.process.start(timeout)

    def stop(self) -> None:
        """Stop the registry: SIGTERM, then SIGKILL if it has not exited within 20 s."""
        self.process.stop()

    def log_tail(self) -> str:
        """The last lines of the registry's log, for error messages."""
        return log_tail(self.process.log_path)


def registry_url_lines(url: str) -> list[str]:
    """The registry's URLs, each labelled with what it is for (``stack up``/``status``, the demo).

    ``url`` is the Confluent-compatible one; an Apicurio Registry also has its native API.
    """
    lines = [f"{url}   Confluent-compatible API: fleetlink, confluent-kafka, Quix Streams, fleetlink kafka"]
    native = apicurio_native_url(url)
    if native is not None:
        lines.append(f"{native}   Apicurio native API: Apicurio's Java serdes (apicurio.registry.url)")
    return lines
