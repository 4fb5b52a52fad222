"""``fleetlink spool check`` reads a spool without changing it and says what is damaged;
``fleetlink spool acknowledge`` clears the findings of a stopped edge's spool."""

from __future__ import annotations

import hashlib
import json
from pathlib import Path
from typing import Any

import pytest

from fleetlink.cli import main
from fleetlink.edge.spool import Spool, SpoolOptions

OPTIONS = SpoolOptions(segment_bytes=8192, max_bytes=1 << 20, group_records=1)


def edge_spool(spool_dir: Path, records: int = 200, acked: int = 0) -> list[Path]:
    """A stopped edge's ``spool.dir``: the durable stream under ``durable/``."""
    with Spool(spool_dir / "durable", OPTIONS) as spool:
        for _ in range(records):  # one append at a time: they fill several segments
            spool.append(b"x" * 100)
        if acked:
            batch = spool.read_unacked(acked, 1 << 20)
            assert batch is not None
            spool.ack(batch.first_seq)
    return sorted((spool_dir / "durable").glob("*.seg"))


def contents(directory: Path) -> dict[str, str]:
    return {p.name: hashlib.sha256(p.read_bytes()).hexdigest() for p in sorted(directory.iterdir())}


def check(path: Path, capsys: pytest.CaptureFixture[str]) -> tuple[int, dict[str, Any]]:
    code = main(["spool", "check", str(path)])
    return code, json.loads(capsys.readouterr().out)


def test_a_healthy_spool_checks_ok(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    segments = edge_spool(tmp_path, acked=10)
    code, result = check(tmp_path, capsys)
    assert code == 0
    assert result["ok"] is True
    assert result["directory"] == str(tmp_path / "durable")
    assert [s["file"] for s in result["segments"]] == [p.name for p in segments]
    assert result["segments"][0]["first_seq"] == 1
    assert result["segments"][-1]["last_seq"] == 200
    assert (result["records"], result["unacknowledged"]) == (200, 190)
    assert result["ledger"]["ack_mark"] == 10
    assert result["ledger"]["clean_stop"] is True
    assert result["damage"] == []


def test_check_finds_damage_changes_nothing_and_fails(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    segments = edge_spool(tmp_path)
    lost = range(int(segments[1].name[:20]), int(segments[2].name[:20]))
    segments[1].unlink()
    last = segments[-1]
    last.write_bytes(last.read_bytes()[:-30])  # the newest cut short within what the ledger knew
    before = contents(tmp_path / "durable")
    code, result = check(tmp_path / "durable", capsys)
    assert code == 1
    assert result["ok"] is False
    assert contents(tmp_path / "durable") == before  # read only: nothing truncated, nothing written
    damage = {(d["reason"], d["file"]): d for d in result["damage"]}
    missing = damage["segment_missing", segments[1].name]
    assert (missing["first_seq"], missing["last_seq"], missing["records"]) == (lost[0], lost[-1], len(lost))
    cut = damage["truncated", last.name]
    assert (cut["first_seq"], cut["last_seq"], cut["records"]) == (200, 200, 1)
    assert result["records_lost"] == len(lost) + 1
    assert result["records"] == 200 - len(lost) - 1


def test_acknowledging_a_stopped_edges_spool(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    segments = edge_spool(tmp_path)
    segments[1].unlink()
    Spool(tmp_path / "durable", OPTIONS).open().close()  # the edge saw it: reported, still waiting
    code, result = check(tmp_path, capsys)
    assert code == 1
    assert [f["reason"] for f in result["awaiting_acknowledgement"]] == ["segment_missing"]
    assert main(["spool", "acknowledge", str(tmp_path)]) == 0
    (done,) = json.loads(capsys.readouterr().out)["acknowledged"]
    assert done["file"] == segments[1].name
    code, result = check(tmp_path, capsys)
    assert (code, result["ok"], result["awaiting_acknowledgement"]) == (0, True, [])
    with Spool(tmp_path / "durable", OPTIONS) as spool:
        assert spool.stats().damage_unacknowledged == 0


def test_acknowledging_a_spool_in_use_is_refused(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    edge_spool(tmp_path)
    with Spool(tmp_path / "durable", OPTIONS):
        code, result = check(tmp_path, capsys)
        assert (code, result["in_use"]) == (0, True)
        assert main(["spool", "acknowledge", str(tmp_path)]) == 1
        assert "open by a running edge" in capsys.readouterr().err


def test_check_of_something_else(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    code, result = check(tmp_path / "nowhere", capsys)
    assert code == 2
    assert result["error"] == "not a directory"
