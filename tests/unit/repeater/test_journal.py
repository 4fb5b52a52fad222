"""The repeater's state directory: replay, torn lines, compaction, and what survives a restart."""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import pytest

from fleetlink.repeater.errors import JournalError
from fleetlink.repeater.journal import (
    FILENAME,
    Journal,
    acked_line,
    command_line,
    mark_line,
    replay,
    status_line,
)
from fleetlink.repeater.state import CommandStore
from fleetlink.wire.commands import CommandEnvelope, StatusEvent

ENV = CommandEnvelope(
    command_id="c1",
    robot="tb4_01",
    ros_topic="/tb4_01/cmd_lightring",
    ros_type="irobot_create_msgs/msg/LightringLeds",
    mapping="lightring",
    issued_at_ms=1_000_000,
    lease_until_ms=1_010_000,
    period_ms=1000,
    schema_fp=b"\x07" * 8,
    body=b"\x01\x02",
    schema='{"s": 1}',
)
EVENT = StatusEvent("c1", "tb4_01", "/tb4_01/cmd_lightring", "delivered", 1_000_500, "site-a", "publish #1")


def lines(*entries: dict[str, object]) -> list[bytes]:
    return [json.dumps(e).encode() for e in entries]


def test_replay_rebuilds_commands_marks_and_pending_statuses() -> None:
    other = replace(ENV, command_id="c2")
    state = replay(
        lines(
            command_line(ENV, 1000.5),
            command_line(other, 1001.0),
            mark_line("delivered", "c1", "tb4_01"),
            mark_line("end", "c2", "tb4_01"),
            status_line(1, EVENT),
            status_line(2, EVENT),
            acked_line(1),
        )
    )
    assert state.commands[("c1", "tb4_01")].envelope == ENV.without_schema()
    assert state.commands[("c1", "tb4_01")].received_at == 1000.5
    first = state.commands[("c1", "tb4_01")]
    assert (first.delivered, first.ended) == (True, False)
    assert state.commands[("c2", "tb4_01")].ended
    assert state.pending == {2: EVENT}
    assert state.next_status == 3
    assert (state.lines, state.skipped) == (7, 0)


@pytest.mark.parametrize(
    "bad",
    [
        b'{"op": "cmd", "env": "!!!", "rx": 1}',  # not base64
        b'{"op": "cmd", "env": "RkxD", "rx": 1}',  # not an envelope
        b'{"op": "teleport"}',
        b'{"op": "status", "n": 1, "ev": {"status": "lost"}}',
        b'{"op": "acked"}',
        b'{"op": "cmd", "env',  # torn last line
    ],
)
def test_unreadable_lines_are_counted_and_skipped(bad: bytes) -> None:
    state = replay([*lines(command_line(ENV, 1.0)), bad])
    assert (state.lines, state.skipped) == (2, 1)
    assert list(state.commands) == [("c1", "tb4_01")]


def test_marks_for_unknown_commands_are_ignored() -> None:
    state = replay(lines(mark_line("end", "nope", "tb4_01")))
    assert state.commands == {}


def test_store_survives_a_restart_and_keeps_schemas_once(tmp_path: Path) -> None:
    store = CommandStore(tmp_path)
    store.open()
    store.command(ENV, 1000.0)
    store.command(replace(ENV, command_id="c2"), 1000.1, ended=True)
    store.mark(("c1", "tb4_01"), "delivered")
    number = store.status(EVENT)
    store.status(EVENT)
    store.acked([number])
    store.close()
    text = (tmp_path / FILENAME).read_text()
    assert text.count('"op":"schema"') == 1

    again = CommandStore(tmp_path)
    again.open()
    assert again.schemas == {ENV.schema_fp: '{"s": 1}'}
    assert again.commands[("c1", "tb4_01")].delivered
    assert again.commands[("c2", "tb4_01")].ended
    assert list(again.pending) == [number + 1]
    assert again.status(EVENT) == number + 2  # numbering continues
    again.close()


def test_compaction_drops_what_is_over_and_keeps_what_is_live(tmp_path: Path) -> None:
    store = CommandStore(tmp_path)
    store.open()
    over = replace(ENV, command_id="old", lease_until_ms=1_001_000)
    store.command(over, 1000.0, ended=True)
    store.command(ENV, 1000.0)
    for _ in range(5):
        store.acked([store.status(EVENT)])
    assert store.journal_lines > 10
    assert store.maybe_compact(now=1005.0, force=True)
    assert ("old", "tb4_01") not in store.commands
    store.close()
    again = CommandStore(tmp_path)
    state = again.open()
    assert list(state.commands) == [("c1", "tb4_01")]
    assert state.pending == {}
    assert state.schemas == {ENV.schema_fp: '{"s": 1}'}
    assert again.journal_lines == 2  # schema + command
    assert not again.maybe_compact(now=1005.0)  # small journal: left alone
    again.close()


def test_an_unusable_state_dir_is_a_journal_error(tmp_path: Path) -> None:
    blocker = tmp_path / "file"
    blocker.write_text("x")
    with pytest.raises(JournalError, match="repeater state"):
        Journal(blocker / "state").open()
    journal = Journal(tmp_path / "ok")
    with pytest.raises(JournalError, match="not open"):
        journal.append(acked_line(1))


def test_a_failing_disk_stops_commands_but_not_status_bookkeeping(tmp_path: Path) -> None:
    store = CommandStore(tmp_path)
    store.open()
    store.command(ENV, 1000.0)
    store.close()  # from here on every write fails
    store.mark(("c1", "tb4_01"), "delivered")
    number = store.status(EVENT)
    store.acked([number])
    assert store.failures == 3
    assert store.commands[("c1", "tb4_01")].delivered  # memory stays right
    with pytest.raises(JournalError, match="not open"):
        store.command(replace(ENV, command_id="c2"), 1001.0)


def test_failed_compaction_keeps_the_old_file_in_use(tmp_path: Path) -> None:
    journal = Journal(tmp_path / "s")
    journal.open()
    journal.append(acked_line(1))
    (tmp_path / "s" / "commands.compact").mkdir()  # the temp file cannot be written
    with pytest.raises(JournalError, match="compaction failed"):
        journal.compact([acked_line(2)])
    journal.append(acked_line(3))  # still open
    journal.close()
    assert replay((tmp_path / "s" / FILENAME).read_bytes().splitlines()).lines == 2
