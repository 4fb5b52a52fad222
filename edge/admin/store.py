"""The overlay file: admin changes that survive a restart, written atomically.

Default place: ``admin-overlay.yaml`` in the spool directory's parent (next to the spool, on the
same disk, outside the spool's own files). Each save writes a temporary file in the same folder,
fsyncs it, renames it over the old one and fsyncs the folder: a crash leaves the old or the new
overlay, never a mix.
"""

from __future__ import annotations

import os
import tempfile
from pathlib import Path

import yaml
from pydantic import ValidationError

from fleetlink.edge.admin.errors import OverlayError, PersistError
from fleetlink.edge.admin.overlay import Overlay
from fleetlink.edge.admin.problems import problems_from

OVERLAY_NAME = "admin-overlay.yaml"
_HEADER = (
    "# Changes made through the fleetlink admin API, applied on top of the config file at start.\n"
    "# Written by the edge agent; edit only while it is stopped (or delete it to start from the\n"
    "# config file alone).\n"
)


def default_overlay_path(spool_dir: Path) -> Path:
    """``<spool.dir>/../admin-overlay.yaml``."""
    return spool_dir.resolve().parent / OVERLAY_NAME


class OverlayStore:
    """The overlay file at ``path``: loads the saved admin changes and saves new ones atomically."""

    def __init__(self, path: Path) -> None:
        self.path = path

    def load(self) -> Overlay:
        """The saved overlay; an empty one when the file does not exist."""
        try:
            text = self.path.read_text(encoding="utf-8")
        except FileNotFoundError:
            return Overlay()
        except OSError as exc:
            raise OverlayError(f"{self.path}: cannot read the admin overlay: {exc.strerror}") from None
        try:
            data = yaml.safe_load(text)
        except yaml.YAMLError as exc:
            raise OverlayError(f"{self.path}: the admin overlay is not valid YAML: {exc}") from None
        try:
            return Overlay.model_validate(data or {})
        except ValidationError as exc:
            listing = "; ".join(f"{p.path}: {p.message}" for p in problems_from(exc, data))
            raise OverlayError(f"{self.path}: invalid admin overlay: {listing}") from None

    def save(self, overlay: Overlay) -> None:
        """Replace the file atomically; raises ``PersistError`` (the old file stays) on failure."""
        text = _HEADER + yaml.safe_dump(overlay.model_dump(mode="json"), sort_keys=False, allow_unicode=True)
        folder = self.path.parent
        tmp: str | None = None
        try:
            folder.mkdir(parents=True, exist_ok=True)
            fd, tmp = tempfile.mkstemp(prefix=f".{self.path.name}.", suffix=".tmp", dir=folder)
            with os.fdopen(fd, "w", encoding="utf-8") as handle:
                handle.write(text)
                handle.flush()
                os.fsync(handle.fileno())
            os.replace(tmp, self.path)
            tmp = None
            dir_fd = os.open(folder, os.O_RDONLY)
            try:
                os.fsync(dir_fd)
            finally:
                os.close(dir_fd)
        except OSError as exc:
            raise PersistError(
                f"cannot save the admin overlay to {self.path}: {exc.strerror}; the change was not applied"
            ) from None
        finally:
            if tmp is not None:
                Path(tmp).unlink(missing_ok=True)
