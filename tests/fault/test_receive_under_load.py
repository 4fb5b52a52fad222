"""The edge takes every sample at 10,000 messages/s and never re-creates its subscriptions.

Twenty robots publish five topics each at 100 Hz (10,000 messages/s, five message types), with
reliable, blocking publishers so that nothing may be dropped on the way. Every message reaches
the spool (lost 0: no sequence gap, nothing dropped at the intake), and the edge received all of
it on the key expressions it declared at start: none was dropped and declared again. The receive
thread read the steady stream with far fewer wake-ups than samples (``intake.coalesce``, on by
default), and losing none on the way.

An intake far too small for the rate drops samples, and each is counted once: as dropped at the
intake, not again as a sequence gap when its publisher's next sample is taken.
"""

from __future__ import annotations

from pathlib import Path

from tests.fault.soak import run_fleet


def test_ten_thousand_messages_a_second_all_reach_the_spool(tmp_path: Path) -> None:
    spool = {"segment_bytes": "16MiB", "max_bytes": "512MiB"}
    run = run_fleet(
        tmp_path, "load", robots=20, topics=5, hz=100.0, seconds=15.0, warmup_s=3.0, spool=spool, block=True
    )
    print("\n" + run.summary())
    accounted = run.accounted()
    assert run.published >= 0.95 * 20 * 5 * 100 * 15, "the robots did not publish at 10,000 messages/s"
    assert accounted["lost in transit (sequence gaps)"] == 0, accounted
    assert accounted["dropped at the intake"] == 0, accounted
    assert accounted["held in the spool"] == run.published + run.registrations, accounted
    edge_log = (tmp_path / "edge.log").read_text()
    assert edge_log.count("receiving ") == 5, "one key expression per mapping, declared once"
    assert "stopped receiving" not in edge_log
    coalesced = run.count("intake", "coalesced")
    assert 0 < coalesced < run.published / 3, f"{coalesced} waits for {run.published} samples"


def test_samples_dropped_at_the_intake_are_counted_once(tmp_path: Path) -> None:
    spool = {"segment_bytes": "16MiB", "max_bytes": "512MiB"}
    run = run_fleet(
        tmp_path,
        "small intake",
        robots=4,
        topics=1,
        hz=1000.0,
        seconds=8.0,
        warmup_s=2.0,
        spool=spool,
        block=True,  # nothing lost on the way: every gap the edge sees is its own intake's doing
        intake={"max_samples": 8},
    )
    print("\n" + run.summary())
    accounted = run.accounted()
    assert accounted["dropped at the intake"] > 0, accounted  # the intake was too small for the rate
    assert accounted["lost in transit (sequence gaps)"] == 0, accounted
    assert sum(accounted.values()) == run.published + run.registrations, accounted
