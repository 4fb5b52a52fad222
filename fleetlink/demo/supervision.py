"""Keep a stream app running: start it again when it stops on an error, a bounded number of times.

A Kafka stream app that dies leaves the fleet without its fault detection until someone notices;
the demo restarts it, says so, and gives up (raising the last error) after ``attempts`` runs.
Observed: Quix Streams 3.28 can stop on a ``KeyError`` when its consumer hands a changelog
record to the data path (its buffered poll during a rebalance); a new run recovers its state
from the changelog and goes on.
"""

from __future__ import annotations

import threading
from collections.abc import Callable


def run_restarting(
    run: Callable[[], object],
    *,
    attempts: int,
    stop: threading.Event,
    on_restart: Callable[[BaseException, int], object],
) -> None:
    """Call ``run`` until it returns, ``stop`` is set, or it raised ``attempts`` times (the last
    error propagates). ``on_restart(error, attempt)`` hears each error that is followed by a
    new run."""
    for attempt in range(1, attempts + 1):
        try:
            run()
            return
        except Exception as exc:
            if stop.is_set():
                return
            if attempt == attempts:
                raise
            on_restart(exc, attempt)
