"""What the repeater remembers of service calls and action goals: ``<state_dir>/calls.journal``.

One JSON object per line (the file format of :mod:`repeater.journal`):

* ``call`` — a call was accepted (its envelope without the payload, when it was received);
  fsynced before the uplink is told, so a call is made at most once per id, restarts included;
* ``done`` — the call has its final outcome;
* ``out`` / ``acked`` — an outcome waiting for the uplink / acknowledged by it (feedback is
  not journalled: it is sent at most once).

A call's id is remembered until its deadline has passed (the uplink forwards nothing later).
Not thread-safe: the repeater calls it under its lock.
"""

from __future__ import annotations

import json
import logging
from collections.abc import Iterable
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

from fleetlink.repeater.errors import JournalError
from fleetlink.repeater.journal import Journal
from fleetlink.wire.calls import (
    CallEnvelope,
    Outcome,
    call_fields,
    check_call,
    outcome_from_json,
    outcome_to_json,
)
from fleetlink.wire.errors import EnvelopeError

log = logging.getLogger(__name__)

FILENAME = "calls.journal"
COMPACT_MIN_LINES = 1_000
CallIdent = tuple[str, str, str]
"""(kind, call id, robot)."""


def ident(env: CallEnvelope) -> CallIdent:
    """The key a call is remembered by: (kind, call id, robot)."""
    return (env.kind, env.call_id, env.robot)


@dataclass
class StoredCall:
    """An accepted call without its payload, when it was received (seconds since the epoch) and whether it
    has its final outcome."""

    envelope: CallEnvelope
    received_at: float
    done: bool = False


@dataclass
class CallState:
    """What replaying the call journal gives: the calls, the unacknowledged outcomes by number, the next
    outcome number, and how many lines were read and skipped."""

    calls: dict[CallIdent, StoredCall] = field(default_factory=dict)
    pending: dict[int, Outcome] = field(default_factory=dict)
    next_number: int = 1
    lines: int = 0
    skipped: int = 0


def call_line(env: CallEnvelope, received_at: float) -> dict[str, Any]:
    """The journal line saying ``env`` was accepted at ``received_at`` (its payload left out)."""
    return {"op": "call", **call_fields(env), "rx": received_at}


def replay_calls(lines: Iterable[bytes]) -> CallState:
    """The state a sequence of lines describes; unreadable lines are counted and skipped."""
    state = CallState()
    for raw in lines:
        state.lines += 1
        try:
            _apply(state, json.loads(raw))
        except (ValueError, KeyError, TypeError, EnvelopeError) as exc:
            state.skipped += 1
            log.warning("repeater call journal: skipping unreadable line %d (%s)", state.lines, exc)
    return state


def _apply(state: CallState, obj: Any) -> None:
    op = obj["op"]
    if op == "call":
        env = CallEnvelope(
            obj["kind"],
            str(obj["id"]),
            str(obj["robot"]),
            str(obj["name"]),
            str(obj["type"]),
            str(obj["mapping"]),
            int(obj["issued"]),
            int(obj["deadline"]),
            b"" if obj["kind"] == "cancel" else b"\x00\x01\x00\x00",  # the payload is not kept
        )
        check_call(env)
        state.calls[ident(env)] = StoredCall(replace(env, payload=b""), float(obj["rx"]))
    elif op == "done":
        stored = state.calls.get((str(obj["kind"]), str(obj["id"]), str(obj["robot"])))
        if stored is not None:
            stored.done = True
    elif op == "out":
        number = int(obj["n"])
        state.pending[number] = outcome_from_json(obj["o"])
        state.next_number = max(state.next_number, number + 1)
    elif op == "acked":
        state.pending.pop(int(obj["n"]), None)
    else:
        raise ValueError(f"unknown op {op!r}")


class CallStore:
    """The calls this repeater accepted and the outcomes waiting for the uplink, mirrored in
    ``calls.journal``.

    Not thread-safe: the repeater calls it under its lock.
    """

    def __init__(self, state_dir: Path) -> None:
        self._journal = Journal(state_dir, FILENAME)
        self.calls: dict[CallIdent, StoredCall] = {}
        self.pending: dict[int, Outcome] = {}
        self._journalled: set[int] = set()
        self._next = 1
        self.skipped_lines = 0

    def open(self) -> None:
        """Replay ``calls.journal`` into memory, then open it for appending; raises ``JournalError`` when it
        cannot be read or opened."""
        path = self._journal.path
        state = CallState()
        try:
            if path.exists():
                with path.open("rb") as existing:
                    state = replay_calls(line for line in existing if line.strip())
        except OSError as exc:
            raise JournalError(str(path), exc.strerror or str(exc)) from None
        self._journal.open(read=False)
        self._journal.lines = state.lines
        self.calls, self.pending = state.calls, state.pending
        self._journalled = set(state.pending)
        self._next = state.next_number
        self.skipped_lines = state.skipped

    def close(self) -> None:
        """Close the journal file; appends fail until it is opened again."""
        self._journal.close()

    def accept(self, env: CallEnvelope, now: float) -> None:
        """Remember ``env`` as accepted at ``now`` and journal it (not yet durable: call :meth:`sync`)."""
        self.calls[ident(env)] = StoredCall(replace(env, payload=b""), now)
        self._journal.append(call_line(env, now))

    def done(self, key: CallIdent) -> None:
        """Mark the call ``key`` as finished and journal that once (an unknown call is ignored)."""
        stored = self.calls.get(key)
        if stored is not None and not stored.done:
            stored.done = True
            self._journal.append({"op": "done", "kind": key[0], "id": key[1], "robot": key[2]})

    def outcome(self, out: Outcome, *, durable: bool = True) -> int:
        """A number for ``out`` (journalled unless it is feedback or ``durable`` is False)."""
        number = self._next
        self._next += 1
        if durable and out.kind != "feedback":
            self.pending[number] = out
            self._journalled.add(number)
            self._journal.append({"op": "out", "n": number, "o": outcome_to_json(out)})
        return number

    def acked(self, numbers: list[int]) -> None:
        """Drop the journalled outcomes the uplink acknowledged and journal that (other numbers: ignored)."""
        lines = []
        for number in numbers:
            if number in self._journalled:
                self._journalled.discard(number)
                self.pending.pop(number, None)
                lines.append({"op": "acked", "n": number})
        if lines:
            self._journal.append(*lines)

    def sync(self) -> None:
        """fsync the journal: the accepted calls and outcomes written so far become durable."""
        self._journal.sync()

    def forget_before(self, now_ms: int) -> None:
        """Drop finished calls whose deadline has passed; compact the file when it is mostly dead."""
        for key, stored in list(self.calls.items()):
            if stored.done and stored.envelope.deadline_ms < now_ms:
                del self.calls[key]
        live = len(self.calls) * 2 + len(self.pending)
        if self._journal.lines < max(COMPACT_MIN_LINES, 4 * live):
            return
        lines: list[dict[str, Any]] = []
        for key, stored in self.calls.items():
            lines.append(call_line(stored.envelope, stored.received_at))
            if stored.done:
                lines.append({"op": "done", "kind": key[0], "id": key[1], "robot": key[2]})
        lines += [{"op": "out", "n": n, "o": outcome_to_json(o)} for n, o in sorted(self.pending.items())]
        self._journal.compact(lines)
