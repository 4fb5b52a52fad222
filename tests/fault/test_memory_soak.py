"""Memory stays bounded and every message is accounted for, whatever the backlog (issue rows 4-6).

Ten robots publish 5,000 Imu messages/s in all into an edge whose WAN is cut and whose 4 MiB
spool fills in about two seconds; for each full policy the edge's resident memory, sampled
after the warm-up, grows by at most 10 %, and every message published is either lost in transit
(counted from sequence numbers), dropped at the intake, held in the spool, evicted or refused by
the spool — each counted once. ``bench/bench_soak.py`` runs the same for minutes.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from tests.fault.soak import run_soak


@pytest.mark.parametrize("policy", ["block", "drop_oldest", "drop_newest"])
def test_a_full_spool_under_5k_msgs_keeps_memory_bounded_and_counts_everything(
    tmp_path: Path, policy: str
) -> None:
    soak = run_soak(tmp_path, policy, robots=10, hz=500.0, seconds=20.0)
    print("\n" + soak.summary())
    assert soak.published >= 0.9 * 10 * 500 * 20, "the robots did not publish at 5,000 messages/s"
    accounted = soak.accounted()
    assert sum(accounted.values()) == soak.published + soak.registrations, accounted
    held = accounted["held in the spool"]
    assert 0 < held < soak.published / 4  # the spool is full and small: the rest was counted away
    if policy == "drop_oldest":
        assert accounted["evicted (drop_oldest)"] > 0
    elif policy == "drop_newest":
        assert accounted["dropped by the spool (drop_newest)"] > 0
    else:
        assert accounted["refused by the spool (block)"] > 0
    assert soak.growth() <= 1.10, soak.summary()
