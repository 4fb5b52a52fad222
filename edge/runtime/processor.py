"""The processing thread: intake -> records -> the buffer of each record's delivery class.

One thread, so the records of a robot are appended in the order their samples arrived. It takes
items from the ``Intake`` in chunks, turns them into records (``RecordMaker``), ticks the stages
a few times a second, and appends each chunk with one ``append_many`` per buffer. A full spool
under the ``block`` policy makes this thread wait (up to the spool's ``block_timeout``) while
the intake fills up and then drops, counted: the Zenoh callbacks never wait.
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass, fields

from fleetlink.common.ratelimit import LogLimiter
from fleetlink.edge.errors import SpoolError, SpoolFullError
from fleetlink.edge.mapping import Delivery
from fleetlink.edge.runtime.intake import Intake
from fleetlink.edge.runtime.outgoing import Outgoing
from fleetlink.edge.runtime.records import RecordMaker
from fleetlink.edge.spool import RecordBuffer
from fleetlink.roswire.errors import RoswireError
from fleetlink.roswire.subscriber import RosSample

log = logging.getLogger(__name__)


@dataclass(frozen=True, slots=True)
class Rejected:
    """A sample a subscriber refused (``on_error``), with the topic it was subscribed on."""

    topic: str
    error: RoswireError
    received_ns: int


@dataclass(frozen=True, slots=True)
class Emit:
    """Records made outside the processor (registration events), appended in order."""

    records: tuple[Outgoing, ...]


Item = RosSample | Rejected | Emit


@dataclass(slots=True)
class ProcessorStats:
    samples: int = 0
    records: int = 0
    appended: int = 0
    spool_dropped: int = 0
    """Refused by a full buffer's ``drop_newest`` policy."""
    spool_refused: int = 0
    """Not taken because the ``block`` policy timed out, or the record exceeds the buffer's limit."""
    errors: int = 0

    def as_dict(self) -> dict[str, int]:
        return {f.name: getattr(self, f.name) for f in fields(self)}


class Processor:
    def __init__(
        self,
        intake: Intake[Item],
        maker: RecordMaker,
        buffers: Mapping[Delivery, RecordBuffer],
        *,
        on_appended: Callable[[Delivery, float], object] | None = None,
        default_linger_s: float = 0.0,
        tick_interval_s: float = 0.1,
        chunk: int = 512,
        clock_ns: Callable[[], int] = time.time_ns,
    ) -> None:
        self.intake = intake
        self.maker = maker
        self.buffers = buffers
        self._on_appended = on_appended or _nothing
        self.default_linger_s = default_linger_s
        """The linger of records that bring none (the edge passes its ``wan.linger``)."""
        self.tick_interval_s = tick_interval_s
        self.chunk = chunk
        self._clock_ns = clock_ns
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._lock = threading.Lock()
        self._limiter = LogLimiter(log)
        self.stats = ProcessorStats()

    def start(self) -> Processor:
        if self._thread is None:
            self._stop.clear()
            self._thread = threading.Thread(target=self._run, name="edge-processor", daemon=True)
            self._thread.start()
        return self

    def stop(self, timeout_s: float = 10.0) -> None:
        """Process what is queued (the intake should be closed first), then stop."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout_s)
            self._thread = None

    def __enter__(self) -> Processor:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()

    def counters(self) -> dict[str, object]:
        """Thread-safe copies of the maker's and the processor's counters."""
        with self._lock:
            return {
                "processor": self.stats.as_dict(),
                "mappings": {name: c.as_dict() for name, c in self.maker.counters.items()},
                "stages": self.maker.stage_counters(),
                "unknown_type_samples": self.maker.unknown_type_samples,
                "rejected_samples": self.maker.rejected,
            }

    # -- the loop --------------------------------------------------------------------------------
    def _run(self) -> None:
        last_tick = 0
        tick_ns = int(self.tick_interval_s * 1e9)
        while True:
            items = self.intake.take(self.chunk, timeout=self.tick_interval_s)
            if not items and self._stop.is_set():
                return
            now = self._clock_ns()
            try:
                with self._lock:
                    out = self._records(items, now)
                    if now - last_tick >= tick_ns:
                        last_tick = now
                        out.extend(self.maker.tick(now))
                self._append(out)
            except Exception as exc:  # noqa: BLE001 - one bad chunk must not stop the edge; logged, counted
                self.stats.errors += 1
                self._limiter.log(
                    logging.ERROR,
                    "chunk",
                    "edge processor: a chunk of %d item(s) failed: %r",
                    len(items),
                    exc,
                )

    def _records(self, items: list[Item], now_ns: int) -> list[Outgoing]:
        out: list[Outgoing] = []
        extend, make = out.extend, self.maker.make
        for item in items:
            if isinstance(item, RosSample):
                self.stats.samples += 1
                extend(make(item, now_ns))
            elif isinstance(item, Rejected):
                out.extend(self.maker.rejected_sample(item.topic, item.error, item.received_ns))
            else:
                out.extend(item.records)
        return out

    def _append(self, out: list[Outgoing]) -> None:
        if not out:
            return
        self.stats.records += len(out)
        groups: dict[Delivery, list[bytes]] = {}
        lingers: dict[Delivery, float] = {}  # per buffer, the shortest linger of what it got
        default = self.default_linger_s
        for delivery, payload, own in out:
            linger = default if own is None else own
            group = groups.get(delivery)
            if group is None:
                group = groups[delivery] = []
                lingers[delivery] = linger
            elif linger < lingers[delivery]:
                lingers[delivery] = linger
            group.append(payload)
        for delivery, payloads in groups.items():
            self._append_to(delivery, self.buffers[delivery], payloads)
            self._on_appended(delivery, lingers[delivery])

    def _append_to(self, delivery: Delivery, buffer: RecordBuffer, payloads: list[bytes]) -> None:
        stats = self.stats
        try:
            results = buffer.append_many(payloads)
        except SpoolFullError as exc:
            stats.appended += exc.taken
            stats.spool_refused += len(payloads) - exc.taken
            self._limiter.log(
                logging.WARNING,
                f"full-{delivery}",
                "%s buffer full: %d record(s) refused (%s)",
                delivery,
                len(payloads) - exc.taken,
                exc,
            )
            return
        except SpoolError:  # a record above the buffer's size limit: append one by one
            results = []
            for payload in payloads:
                try:
                    results.extend(buffer.append_many([payload]))
                except SpoolError as exc:
                    stats.spool_refused += 1
                    self._limiter.log(
                        logging.WARNING,
                        f"refused-{delivery}",
                        "%s buffer refused a record of %d bytes: %s",
                        delivery,
                        len(payload),
                        exc,
                    )
        taken = sum(1 for r in results if r is not None)
        stats.appended += taken
        stats.spool_dropped += len(results) - taken


def _nothing(_delivery: Delivery, _linger_s: float) -> None:
    """Default ``on_appended``."""
