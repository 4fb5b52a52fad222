"""``Worker``: a loop on a daemon thread, from :meth:`Worker.start` until :meth:`Worker.stop`."""

from __future__ import annotations

import threading
from typing import Self


class Worker:
    """Runs :meth:`_run` on a daemon thread named ``name``; ``_run`` ends once ``_stop`` is set.

    :meth:`start` does nothing while the thread runs; :meth:`stop` sets ``_stop`` and waits up to
    ``join_s`` seconds for the thread, after which the worker may be started again."""

    def __init__(self, name: str, *, join_s: float = 10.0) -> None:
        self._thread_name = name
        self._join_s = join_s
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None

    def start(self) -> Self:
        """Start the thread running ``_run`` unless it runs already; returns ``self``."""
        if self._thread is None:
            self._stop.clear()
            self._thread = threading.Thread(target=self._run, name=self._thread_name, daemon=True)
            self._thread.start()
        return self

    def stop(self) -> None:
        """Set ``_stop`` and wait up to ``join_s`` seconds for the thread to end."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join(self._join_s)
            self._thread = None

    def _run(self) -> None:
        raise NotImplementedError
