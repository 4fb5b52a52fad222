"""Fingerprint -> schema JSON for every value the edge ever spooled, kept on disk.

A batch carries the schema of each fingerprint its records use (until an uplink acknowledged
it), so any stateless uplink can register it. Records outlive the process that made them (the
spool survives restarts), so the book is durable too: a schema is written (fsynced, then
renamed into place) *before* the first record using it is appended, one ``<fingerprint
hex>.json`` file per schema, and read back at start. A file whose content does not hash to its
name is skipped and counted.
"""

from __future__ import annotations

import logging
import threading
from collections.abc import Iterable
from pathlib import Path

from fleetlink.common.durable import write_atomically
from fleetlink.edge.runtime.errors import RuntimeSetupError
from fleetlink.schemas.single_object import fingerprint

log = logging.getLogger(__name__)


class SchemaBook:
    """Thread-safe; ``directory=None`` keeps the book in memory only (tests, no spool)."""

    def __init__(self, directory: Path | None = None) -> None:
        self.directory = directory
        self._lock = threading.Lock()
        self._schemas: dict[bytes, str] = {}
        self.corrupt = 0
        self.write_errors = 0

    def load(self) -> SchemaBook:
        """Create the directory if needed and read every schema in it."""
        if self.directory is None:
            return self
        try:
            self.directory.mkdir(parents=True, exist_ok=True)
            files = sorted(self.directory.glob("*.json"))
        except OSError as exc:
            raise RuntimeSetupError(f"schema book {self.directory}: {exc.strerror or exc}") from None
        for path in files:
            try:
                expected = bytes.fromhex(path.stem)
                text = path.read_text(encoding="utf-8")
                ok = len(expected) == 8 and fingerprint(text) == expected
            except (OSError, ValueError) as exc:
                log.warning("schema book: skipping %s: %s", path, exc)
                ok = False
            if not ok:
                self.corrupt += 1
                continue
            self._schemas[expected] = text
        return self

    def __len__(self) -> int:
        return len(self._schemas)

    def __contains__(self, fp: object) -> bool:
        return fp in self._schemas

    def add(self, fp: bytes, text: str) -> None:
        """Remember ``text`` under ``fp`` (durably, when the book has a directory)."""
        if fp in self._schemas:
            return
        with self._lock:
            if fp in self._schemas:
                return
            if self.directory is not None:
                try:
                    path = self.directory / f"{fp.hex()}.json"
                    write_atomically(
                        path, text.encode("utf-8"), tmp=path.with_suffix(".tmp"), sync_folder=True
                    )
                except OSError as exc:  # kept in memory: records still flow while this process lives
                    self.write_errors += 1
                    log.warning(
                        "schema book: cannot persist schema %s in %s: %s",
                        fp.hex(),
                        self.directory,
                        exc.strerror or exc,
                    )
            self._schemas[fp] = text

    def lookup(self, fps: Iterable[bytes]) -> tuple[dict[bytes, str], list[bytes]]:
        """``(found, missing)`` for the fingerprints a batch uses."""
        found: dict[bytes, str] = {}
        missing: list[bytes] = []
        for fp in fps:
            text = self._schemas.get(fp)
            if text is None:
                missing.append(fp)
            else:
                found[fp] = text
        return found, missing
