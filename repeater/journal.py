"""The repeater's state directory: an append-only journal of commands and status events.

One file, ``<state_dir>/commands.journal``, one JSON object per line:

* ``schema`` — a writer schema's JSON text by fingerprint (written once per fingerprint);
* ``cmd`` — a command applied (its envelope without the schema) and when it was received;
* ``delivered`` / ``end`` — the command was first seen by a subscriber / stopped for good;
* ``status`` / ``acked`` — a status event waiting for the uplink / acknowledged by it.

A command line is fsynced before the uplink is told it was applied, so the uplink commits
only what a restarted repeater will recognise ("applied once" holds across a crash).
:func:`replay` rebuilds the state from the lines (a torn last line is skipped);
:meth:`Journal.compact` rewrites the file with only what is still live (commands whose lease
has not ended, unacknowledged events, the schemas they use), atomically.
"""

from __future__ import annotations

import base64
import binascii
import json
import logging
import os
from collections.abc import Iterable
from dataclasses import dataclass, field
from pathlib import Path
from types import TracebackType
from typing import IO, Any

from fleetlink.repeater.errors import JournalError
from fleetlink.wire.commands import (
    CommandEnvelope,
    StatusEvent,
    decode_envelope,
    encode_envelope,
    status_from_json,
    status_to_json,
)
from fleetlink.wire.errors import EnvelopeError

log = logging.getLogger(__name__)

FILENAME = "commands.journal"


@dataclass
class StoredCommand:
    """A journalled command (its envelope without the schema), when it was received (seconds since the
    epoch) and whether it was delivered and has ended."""

    envelope: CommandEnvelope
    received_at: float
    delivered: bool = False
    ended: bool = False


@dataclass
class JournalState:
    """What replaying a command journal gives: schemas by fingerprint, commands by (id, robot), the
    unacknowledged status events by number, the next number, and the lines read and skipped."""

    schemas: dict[bytes, str] = field(default_factory=dict)
    commands: dict[tuple[str, str], StoredCommand] = field(default_factory=dict)
    pending: dict[int, StatusEvent] = field(default_factory=dict)
    next_status: int = 1
    lines: int = 0
    skipped: int = 0

    def live_lines(self) -> int:
        """About how many lines a compacted journal of this state holds (a command counted with one mark)."""
        return len(self.schemas) + 2 * len(self.commands) + len(self.pending)


# -- lines (pure) ---------------------------------------------------------------------------


def schema_line(fp: bytes, text: str) -> dict[str, Any]:
    """The journal line keeping the writer schema ``text`` under its fingerprint ``fp``."""
    return {"op": "schema", "fp": fp.hex(), "text": text}


def command_line(env: CommandEnvelope, received_at: float) -> dict[str, Any]:
    """The journal line for a command received at ``received_at``, without its schema."""
    raw = encode_envelope(env.without_schema(), compress_above=1 << 30)
    return {"op": "cmd", "env": base64.b64encode(raw).decode(), "rx": received_at}


def mark_line(op: str, command_id: str, robot: str) -> dict[str, Any]:
    """The journal line marking a command ``delivered`` or ``end``."""
    return {"op": op, "id": command_id, "robot": robot}


def status_line(number: int, event: StatusEvent) -> dict[str, Any]:
    """The journal line for status event ``number``, waiting for the uplink."""
    return {"op": "status", "n": number, "ev": status_to_json(event)}


def acked_line(number: int) -> dict[str, Any]:
    """The journal line saying the uplink acknowledged status event ``number``."""
    return {"op": "acked", "n": number}


def replay(lines: Iterable[bytes]) -> JournalState:
    """The state a sequence of journal lines describes; bad lines are counted and skipped."""
    state = JournalState()
    for raw in lines:
        state.lines += 1
        try:
            _apply(state, json.loads(raw))
        except (ValueError, KeyError, TypeError, binascii.Error, EnvelopeError) as exc:
            state.skipped += 1
            log.warning("repeater journal: skipping unreadable line %d (%s)", state.lines, exc)
    return state


def _apply(state: JournalState, obj: Any) -> None:
    op = obj["op"]
    if op == "schema":
        state.schemas[bytes.fromhex(obj["fp"])] = str(obj["text"])
    elif op == "cmd":
        env = decode_envelope(base64.b64decode(obj["env"], validate=True))
        state.commands[(env.command_id, env.robot)] = StoredCommand(env, float(obj["rx"]))
    elif op in ("delivered", "end"):
        stored = state.commands.get((str(obj["id"]), str(obj["robot"])))
        if stored is not None:
            if op == "delivered":
                stored.delivered = True
            else:
                stored.ended = True
    elif op == "status":
        number = int(obj["n"])
        state.pending[number] = status_from_json(obj["ev"])
        state.next_status = max(state.next_status, number + 1)
    elif op == "acked":
        state.pending.pop(int(obj["n"]), None)
    else:
        raise ValueError(f"unknown op {op!r}")


# -- file (I/O) -----------------------------------------------------------------------------


class Journal:
    """The journal file of one state directory; open with :meth:`open`, close with :meth:`close`."""

    def __init__(self, state_dir: Path, filename: str = FILENAME) -> None:
        self.state_dir = state_dir
        self.path = state_dir / filename
        self._file: IO[bytes] | None = None
        self.lines = 0

    def open(self, *, read: bool = True) -> JournalState:
        """Open for appending; with ``read``, first replay the command journal already there."""
        state = JournalState()
        try:
            self.state_dir.mkdir(parents=True, exist_ok=True)
            if read and self.path.exists():
                with self.path.open("rb") as existing:
                    state = replay(line for line in existing if line.strip())
            self._file = self.path.open("ab")
        except OSError as exc:
            raise JournalError(str(self.path), exc.strerror or str(exc)) from None
        self.lines = state.lines
        return state

    def close(self) -> None:
        """Close the file, if open; appends fail until it is opened again."""
        if self._file is not None:
            self._file.close()
            self._file = None

    def __enter__(self) -> Journal:
        return self

    def __exit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        self.close()

    def append(self, *entries: dict[str, Any], sync: bool = False) -> None:
        """Write ``entries`` as lines and flush them (fsynced too with ``sync``).

        Raises ``JournalError`` when the journal is not open or the write fails.
        """
        out = self._file
        if out is None:
            raise JournalError(str(self.path), "journal is not open")
        data = b"".join(_dump(e) for e in entries)
        try:
            out.write(data)
            out.flush()
            if sync:
                os.fsync(out.fileno())
        except OSError as exc:
            raise JournalError(str(self.path), exc.strerror or str(exc)) from None
        self.lines += len(entries)

    def sync(self) -> None:
        """Make what was appended durable (fsync); safe to call without the writer's lock: a file
        replaced by a compaction meanwhile was fsynced by it."""
        out = self._file
        if out is None:
            return
        try:
            os.fsync(out.fileno())
        except ValueError:
            return  # closed by a concurrent compaction, which fsynced its replacement
        except OSError as exc:
            raise JournalError(str(self.path), exc.strerror or str(exc)) from None

    def compact(self, live: list[dict[str, Any]]) -> None:
        """Replace the file by ``live`` (written to a temp file, fsynced, renamed over it).

        On failure the old file stays in use (and open for appends)."""
        tmp = self.path.with_suffix(".compact")
        try:
            with tmp.open("wb") as out:
                out.write(b"".join(_dump(e) for e in live))
                out.flush()
                os.fsync(out.fileno())
        except OSError as exc:
            raise JournalError(str(self.path), f"compaction failed: {exc.strerror or exc}") from None
        self.close()
        try:
            tmp.replace(self.path)
            dir_fd = os.open(self.state_dir, os.O_RDONLY)
            try:
                os.fsync(dir_fd)
            finally:
                os.close(dir_fd)
        except OSError as exc:
            raise JournalError(str(self.path), f"compaction failed: {exc.strerror or exc}") from None
        finally:
            try:
                self._file = self.path.open("ab")
            except OSError as exc:
                raise JournalError(str(self.path), f"cannot reopen: {exc.strerror or exc}") from None
        self.lines = len(live)


def _dump(entry: dict[str, Any]) -> bytes:
    return json.dumps(entry, separators=(",", ":"), ensure_ascii=False).encode() + b"\n"
