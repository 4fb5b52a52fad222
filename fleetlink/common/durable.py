"""Replacing a file so that a crash leaves either the old or the new content, never a mix."""

from __future__ import annotations

import os
from pathlib import Path


def write_atomically(path: Path, data: bytes, *, tmp: Path | None = None, sync_folder: bool = False) -> None:
    """Write ``data`` to ``tmp`` (default: ``path`` + ``.tmp``), fsync it and rename it to ``path``;
    with ``sync_folder`` also fsync the folder, so the rename itself survives a power loss.
    Raises ``OSError``."""
    tmp = path.with_name(path.name + ".tmp") if tmp is None else tmp
    fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o644)
    try:
        view = memoryview(data)
        while view:
            view = view[os.write(fd, view) :]
        os.fsync(fd)
    finally:
        os.close(fd)
    os.replace(tmp, path)
    if sync_folder:
        dir_fd = os.open(path.parent, os.O_RDONLY)
        try:
            os.fsync(dir_fd)
        finally:
            os.close(dir_fd)
