"""An S3-compatible object store on loopback: s3proxy (Maven Central) over a local folder.

s3proxy serves the S3 API (Signature V2 and V4, path-style requests) in front of jclouds'
``filesystem`` provider: each bucket is a folder, each object a file. It is a real S3 server as
far as fleetlink's client can tell; the edge's claim checks and the console read and write it
exactly as they would AWS S3 or MinIO.
"""

from __future__ import annotations

import secrets
from dataclasses import dataclass, field
from pathlib import Path

import httpx
from pydantic import SecretStr

from fleetlink.common.lifecycle import StartStop
from fleetlink.common.objects import ObjectStore, ObjectStoreSection
from fleetlink.localstack.artifacts import fetch_s3proxy
from fleetlink.localstack.java import KAFKA_MIN_JAVA, find_java
from fleetlink.localstack.process import ServerProcess, ensure_port_free, free_port, log_tail

DEFAULT_BUCKET = "fleetlink-objects"


@dataclass(frozen=True)
class ObjectStoreSettings:
    """Where s3proxy listens and keeps its objects, its bucket and credentials (a random secret)."""

    port: int
    data_dir: Path
    host: str = "127.0.0.1"
    bucket: str = DEFAULT_BUCKET
    access_key_id: str = "fleetlink"
    secret_access_key: str = field(default_factory=lambda: secrets.token_hex(16))

    @property
    def endpoint(self) -> str:
        """The store's base URL, ``http://host:port``."""
        return f"http://{self.host}:{self.port}"


class ObjectStoreServer(StartStop):
    """s3proxy as a process: ``start`` returns once it answers and the bucket exists."""

    def __init__(
        self, settings: ObjectStoreSettings, jar: Path | None = None, java: str | None = None
    ) -> None:
        self.settings = settings
        self._jar = jar
        self._java = java
        self.process: ServerProcess | None = None

    @property
    def endpoint(self) -> str:
        """The store's base URL, ``http://host:port``."""
        return self.settings.endpoint

    def section(self, **overrides: object) -> ObjectStoreSection:
        """An ``objects:`` section that reaches this store (``overrides``: other keys of it)."""
        s = self.settings
        data: dict[str, object] = {
            "endpoint": s.endpoint,
            "bucket": s.bucket,
            "access_key_id": s.access_key_id,
            "secret_access_key": SecretStr(s.secret_access_key),
            **overrides,
        }
        return ObjectStoreSection.model_validate(data)

    def config_data(self, **overrides: object) -> dict[str, object]:
        """The same as plain data, for a YAML config file."""
        s = self.settings
        return {
            "endpoint": s.endpoint,
            "bucket": s.bucket,
            "access_key_id": s.access_key_id,
            "secret_access_key": s.secret_access_key,
            **overrides,
        }

    def _properties(self) -> Path:
        s = self.settings
        blobs = s.data_dir / "blobs"
        blobs.mkdir(parents=True, exist_ok=True)
        path = s.data_dir / "s3proxy.conf"
        path.write_text(
            "\n".join(
                (
                    f"s3proxy.endpoint={s.endpoint}",
                    "s3proxy.authorization=aws-v2-or-v4",
                    f"s3proxy.identity={s.access_key_id}",
                    f"s3proxy.credential={s.secret_access_key}",
                    "jclouds.provider=filesystem",
                    f"jclouds.filesystem.basedir={blobs}",
                    "",
                )
            )
        )
        path.chmod(0o600)
        return path

    def _ready(self) -> bool:
        try:
            httpx.get(self.endpoint + "/", timeout=1.0)
        except httpx.HTTPError:
            return False
        return True  # any answer (403 to an unsigned request) means it serves

    def start(self, timeout: float = 60.0) -> float:
        """Run s3proxy (fetching it and finding Java as needed), wait until it answers and create the bucket.

        Returns the seconds the process took to answer; raises ``StackError`` when it does not.
        """
        s = self.settings
        ensure_port_free(s.port, "the object store", s.host)
        s.data_dir.mkdir(parents=True, exist_ok=True)
        jar = self._jar or fetch_s3proxy()
        java = self._java or find_java(KAFKA_MIN_JAVA, "s3proxy")
        self.process = ServerProcess(
            name=f"s3proxy on {s.host}:{s.port}",
            argv=[java, "-Xms64m", "-Xmx384m", "-jar", str(jar), "--properties", str(self._properties())],
            log_path=s.data_dir / "s3proxy.log",
            pid_path=s.data_dir / "s3proxy.pid",
            ready=self._ready,
        )
        took = self.process.start(timeout)
        with ObjectStore(self.section()) as store:
            store.ensure_bucket()
        return took

    def stop(self) -> None:
        """Stop s3proxy if it was started (its objects stay in ``data_dir``)."""
        if self.process is not None:
            self.process.stop()

    def kill(self) -> None:
        """SIGKILL (fault tests); ``start`` again on the same folder keeps every object."""
        if self.process is not None:
            self.process.kill()

    def log_tail(self) -> str:
        """The last lines of s3proxy's log, for error messages."""
        return log_tail(self.settings.data_dir / "s3proxy.log")


def local_object_store(data_dir: Path, port: int | None = None) -> ObjectStoreServer:
    """An s3proxy on a free loopback port (or ``port``) keeping its objects under ``data_dir``."""
    return ObjectStoreServer(ObjectStoreSettings(port=port or free_port(), data_dir=data_dir))
