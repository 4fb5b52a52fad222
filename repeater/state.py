"""What the repeater remembers across restarts, kept in memory and journalled (``journal``).

``CommandStore`` mirrors the journal: writer schemas by fingerprint, every command applied
whose lease has not ended (with its delivered / ended marks, so a restart neither replays a
finished command nor reports it delivered twice), and the status events not yet
acknowledged by the uplink. Not thread-safe: the repeater calls it under its lock.
"""

from __future__ import annotations

import logging
from pathlib import Path
from typing import Any

from fleetlink.common.ratelimit import LogLimiter
from fleetlink.repeater.errors import JournalError
from fleetlink.repeater.journal import (
    Journal,
    JournalState,
    StoredCommand,
    acked_line,
    command_line,
    mark_line,
    schema_line,
    status_line,
)
from fleetlink.wire.commands import CommandEnvelope, StatusEvent

log = logging.getLogger(__name__)

COMPACT_MIN_LINES = 1_000

Ident = tuple[str, str]


class CommandStore:
    """The journalled state in memory: writer schemas, commands whose lease has not ended, and the status
    events not yet acknowledged by the uplink."""

    def __init__(self, state_dir: Path) -> None:
        self._journal = Journal(state_dir)
        self.schemas: dict[bytes, str] = {}
        self.commands: dict[Ident, StoredCommand] = {}
        self.pending: dict[int, StatusEvent] = {}
        self._next = 1
        self.skipped_lines = 0
        self.failures = 0
        self._limiter = LogLimiter(log)

    def open(self) -> JournalState:
        """Open the journal, replay it into memory and return what it held; raises ``JournalError`` when it
        cannot be read or opened."""
        state = self._journal.open()
        self.schemas = dict(state.schemas)
        self.commands = dict(state.commands)
        self.pending = dict(state.pending)
        self._next = state.next_status
        self.skipped_lines = state.skipped
        return state

    def close(self) -> None:
        """Close the journal file; writes fail until it is opened again."""
        self._journal.close()

    # -- writes ---------------------------------------------------------------------------

    def command(self, env: CommandEnvelope, received_at: float, *, ended: bool = False) -> None:
        """Record a command: applied, or refused but to be recognised when re-delivered.

        Written, not yet durable: call :meth:`sync` before telling the uplink."""
        entries: list[dict[str, Any]] = []
        if env.schema is not None and env.schema_fp not in self.schemas:
            self.schemas[env.schema_fp] = env.schema
            entries.append(schema_line(env.schema_fp, env.schema))
        ident = (env.command_id, env.robot)
        self.commands[ident] = StoredCommand(env.without_schema(), received_at, ended=ended)
        entries.append(command_line(env, received_at))
        if ended:
            entries.append(mark_line("end", *ident))
        self._journal.append(*entries)

    def sync(self) -> None:
        """fsync the journal (may run outside the repeater's lock)."""
        self._journal.sync()

    def mark(self, ident: Ident, op: str) -> None:
        """Mark a known command ``delivered`` or ``end`` and journal it (a write failure is counted, not
        raised)."""
        stored = self.commands.get(ident)
        if stored is None:
            return
        if op == "end":
            stored.ended = True
        elif op == "delivered":
            stored.delivered = True
        self._append_softly(mark_line(op, *ident))

    def status(self, event: StatusEvent) -> int:
        """Keep a status event until the uplink acknowledges it and journal it; returns its number."""
        number = self._next
        self._next += 1
        self.pending[number] = event
        self._append_softly(status_line(number, event))
        return number

    def acked(self, numbers: list[int]) -> None:
        """Drop the status events the uplink acknowledged and journal that (a write failure is counted)."""
        done = [n for n in numbers if self.pending.pop(n, None) is not None]
        if done:
            self._append_softly(*(acked_line(n) for n in done))

    def _append_softly(self, *entries: dict[str, Any]) -> None:
        """Marks and status events: a failing disk must not stop repeating and reporting (the
        state stays right in memory; a restart may then report an event twice or miss a mark).
        Commands themselves are journalled strictly (:meth:`command` raises)."""
        try:
            self._journal.append(*entries)
        except JournalError as exc:
            self.failures += 1
            self._limiter.log(logging.ERROR, "journal", "repeater journal write failed: %s", exc)

    # -- compaction -----------------------------------------------------------------------

    def maybe_compact(self, now: float, *, force: bool = False) -> bool:
        """Drop commands whose lease ended; rewrite the journal when it is mostly dead lines."""
        over = [i for i, c in self.commands.items() if c.envelope.lease_until_ms / 1000 <= now and c.ended]
        for ident in over:
            del self.commands[ident]
        live = self.live_entries()
        if not force and self._journal.lines < max(COMPACT_MIN_LINES, 4 * len(live)):
            return False
        self._journal.compact(live)
        return True

    def live_entries(self) -> list[dict[str, Any]]:
        """The lines a compacted journal holds: the schemas in use, each command with its marks,
        the pending status events."""
        used = {c.envelope.schema_fp for c in self.commands.values()}
        entries = [schema_line(fp, text) for fp, text in self.schemas.items() if fp in used]
        for ident, stored in self.commands.items():
            entries.append(command_line(stored.envelope, stored.received_at))
            if stored.delivered:
                entries.append(mark_line("delivered", *ident))
            if stored.ended:
                entries.append(mark_line("end", *ident))
        entries += [status_line(n, e) for n, e in sorted(self.pending.items())]
        return entries

    @property
    def journal_lines(self) -> int:
        """How many lines the journal file holds now."""
        return self._journal.lines
