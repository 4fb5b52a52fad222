"""First-use downloads: progress from Maven's lines, and one fetch at a time per cache folder."""

from __future__ import annotations

import threading
import time
from pathlib import Path

import pytest

from fleetlink.localstack import artifacts
from fleetlink.localstack.artifacts import Progress, cache_lock, downloaded_bytes


@pytest.mark.parametrize(
    ("line", "size"),
    [
        ("[INFO] Downloaded from central: https://repo/x.pom (3.9 kB at 9.7 kB/s)", 3900),
        ("[INFO] Downloaded from central: https://repo/k.jar (1,234 B at 2 MB/s)", 1234),
        ("[INFO] Downloaded from central: https://repo/k.jar (12 MB at 20 MB/s)", 12_000_000),
        ("[INFO] Downloading from central: https://repo/k.jar", None),
        ("[INFO] BUILD SUCCESS", None),
    ],
)
def test_downloaded_sizes(line: str, size: int | None) -> None:
    assert downloaded_bytes(line) == size


def test_progress_is_told_every_few_seconds_then_summed_up() -> None:
    told: list[str] = []
    now = [0.0]
    progress = Progress("Kafka jars", told.append, lambda: now[0], every_s=2.0)
    line = "[INFO] Downloaded from central: https://repo/k.jar (1.5 MB at 2 MB/s)"
    progress.line(line)
    now[0] = 2.5
    progress.line(line)
    progress.line("[INFO] Downloading from central: https://repo/k.jar")
    progress.done()
    assert told == ["  Kafka jars: 2 files, 3.0 MB so far", "  Kafka jars: 2 files, 3.0 MB downloaded"]


def test_one_fetch_at_a_time_and_the_second_finds_the_jars(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    runs: list[str] = []

    def fake_mvn(args: list[str], cwd: Path, what: str) -> None:
        runs.append(what)
        out = Path(next(a for a in args if a.startswith("-DoutputDirectory=")).split("=", 1)[1])
        out.mkdir(parents=True)
        time.sleep(0.3)  # ok-sleep: a slow download, for the other thread to wait on
        (out / "kafka.jar").write_text("jar")

    monkeypatch.setattr(artifacts, "_run_mvn", fake_mvn)
    results: list[Path] = []
    threads = [
        threading.Thread(target=lambda: results.append(artifacts.fetch_kafka(tmp_path))) for _ in range(2)
    ]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join(10)
    assert len(runs) == 1  # the second caller waited and found the jars
    assert results[0] == results[1]
    assert (results[0] / "kafka.jar").read_text() == "jar"
    assert "waiting for another process" in capsys.readouterr().out


def test_the_lock_is_held_across_open_files(tmp_path: Path) -> None:
    order: list[str] = []
    with cache_lock(tmp_path):
        waiter = threading.Thread(target=lambda: _locked(tmp_path, order))
        waiter.start()
        time.sleep(0.2)  # ok-sleep: the waiter blocks on the lock meanwhile
        order.append("first done")
    waiter.join(5)
    assert order == ["first done", "second"]


def _locked(root: Path, order: list[str]) -> None:
    with cache_lock(root):
        order.append("second")
