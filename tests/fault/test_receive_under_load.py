"""The edge takes every sample at 10,000 messages/s and never re-creates its subscriptions.

Twenty robots publish five topics each at 100 Hz (10,000 messages/s, five message types), with
reliable, blocking publishers so that nothing may be dropped on the way. Every message reaches
the spool (lost 0: no sequence gap, nothing dropped at the intake), and the edge received all of
it on the key expressions it declared at start: none was dropped and declared again. The receive
thread read the steady stream with far fewer wake-ups than samples (``intake.coalesce``, on by
default), and losing none on the way.

An intake far too small for the rate drops samples, and each is counted once: as dropped at the
intake, not again as a sequence gap when its publisher's next sample is taken — and only those
drops a gap spans are taken out of it: drops before a publisher's first sample taken never hide
a later loss on the way.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from fleetlink.edge.agent import EdgeAgent
from fleetlink.edge.config import EdgeConfig
from fleetlink.localstack.zenoh_router import ZenohRouter
from fleetlink.roswire import cdr
from fleetlink.roswire.node import RosNode
from fleetlink.schemas.typestore import load_typestore
from tests.fault.soak import Soak, run_fleet
from tests.helpers import wait_until, zenoh_peer_config

STRING = "std_msgs/msg/String"


SPOOL = {"segment_bytes": "16MiB", "max_bytes": "512MiB"}


def assert_all_spooled(run: Soak, rate: float, seconds: float, samples_a_wait: float) -> None:
    """The robots kept ``rate`` messages/s for ``seconds`` (reliable, blocking publishers fall
    behind an edge that reads slower), every message reached the spool (lost 0), and the
    receive thread waited, but less than once every ``samples_a_wait`` samples."""
    print("\n" + run.summary())
    accounted = run.accounted()
    assert run.published >= 0.95 * rate * seconds, f"the robots fell behind {rate:,.0f} messages/s"
    assert accounted["lost in transit (sequence gaps)"] == 0, accounted
    assert accounted["dropped at the intake"] == 0, accounted
    assert accounted["held in the spool"] == run.published + run.registrations, accounted
    coalesced = run.count("intake", "coalesced")
    assert 0 < coalesced < run.published / samples_a_wait, f"{coalesced} waits for {run.published} samples"


def test_ten_thousand_messages_a_second_all_reach_the_spool(tmp_path: Path) -> None:
    run = run_fleet(
        tmp_path, "load", robots=20, topics=5, hz=100.0, seconds=15.0, warmup_s=3.0, spool=SPOOL, block=True
    )
    assert_all_spooled(run, rate=20 * 5 * 100, seconds=15.0, samples_a_wait=3)
    edge_log = (tmp_path / "edge.log").read_text()
    assert edge_log.count("receiving ") == 5, "one key expression per mapping, declared once"
    assert "stopped receiving" not in edge_log


def test_a_long_receive_wait_still_reads_a_steady_fleet_whole(tmp_path: Path) -> None:
    """A 20 ms receive wait at 2,000 messages/s: the receive thread waits only after a sample
    that woke it, and reads on without waiting through the samples that came meanwhile, even
    when it is preempted between two of them on a loaded machine. So the robots keep their rate,
    every message reaches the spool, and there are tens of samples a wait (a thread that waited
    after any gap between two samples read a few samples a wait: 24 % of the rate came through)."""
    intake = {"coalesce": "20ms", "busy_coalesce": "20ms"}
    run = run_fleet(
        tmp_path,
        "long wait",
        robots=20,
        topics=5,
        hz=20.0,
        seconds=10.0,
        warmup_s=2.0,
        spool=SPOOL,
        block=True,
        intake=intake,
    )
    assert_all_spooled(run, rate=20 * 5 * 20, seconds=10.0, samples_a_wait=10)


def test_samples_dropped_at_the_intake_are_counted_once(tmp_path: Path) -> None:
    run = run_fleet(
        tmp_path,
        "small intake",
        robots=4,
        topics=1,
        hz=1000.0,
        seconds=8.0,
        warmup_s=2.0,
        spool=SPOOL,
        block=True,  # nothing lost on the way: every gap the edge sees is its own intake's doing
        intake={"max_samples": 8},
    )
    print("\n" + run.summary())
    accounted = run.accounted()
    assert accounted["dropped at the intake"] > 0, accounted  # the intake was too small for the rate
    assert accounted["lost in transit (sequence gaps)"] == 0, accounted
    assert sum(accounted.values()) == run.published + run.registrations, accounted


def test_drops_before_a_publishers_first_sample_never_hide_a_later_gap(tmp_path: Path) -> None:
    """The edge's processing thread waits on a full spool (``block``) while its 4-sample intake
    is full: robot B's first ten samples are dropped at the intake. Once the spool refuses and the
    thread takes again, B's eleventh sample is its first taken; then B skips five sequence numbers
    (five samples lost on the way): they are counted as missing, not excused by the ten drops
    before its first sample."""
    with ZenohRouter() as router:
        config: dict[str, Any] = {
            "site": "drops",
            "edge_id": "edge-1",
            "zenoh": {"mode": "client", "connect": [router.endpoint]},
            "robot_types": {
                "tb4": {
                    "match": "/tb4_*",
                    "mappings": [
                        {"name": "chatter", "from": "/{robot}/chatter", "to": "fleet.chatter", "type": STRING}
                    ],
                }
            },
            "spool": {
                "dir": str(tmp_path / "spool"),
                "segment_bytes": "4KiB",
                "max_bytes": "8KiB",
                "policy": "block",
                "block_timeout": "5s",
            },
            "intake": {"max_samples": 4},
        }
        typestore = load_typestore("jazzy")
        with (
            EdgeAgent(EdgeConfig.model_validate(config)) as agent,
            RosNode("a", "/tb4_01", config=zenoh_peer_config(router.endpoint), typestore=typestore) as a,
            RosNode("b", "/tb4_02", config=zenoh_peer_config(router.endpoint), typestore=typestore) as b,
        ):
            flood = a.create_publisher("/tb4_01/chatter", STRING, congestion="block")
            late = b.create_publisher("/tb4_02/chatter", STRING, congestion="block")
            for pub in (flood, late):
                wait_until(pub.has_subscribers, 10, message="the edge subscribes")

            def snap() -> dict[str, Any]:
                data: dict[str, Any] = agent.snapshot()
                return data

            # both robots registered before the spool fills: their registrations are records too
            wait_until(lambda: len(snap().get("robots", {})) == 2, 10, message="both robots registered")

            def intake() -> dict[str, int]:
                counts: dict[str, int] = snap()["intake"]
                return counts

            n = 0

            def flood_one_into_a_full_intake() -> bool:
                """One more sample of A: True when the intake was full and nothing was taken."""
                nonlocal n
                before = intake()
                flood.publish_cdr(cdr.encode_string(f"a:{n:0100d}"))
                n += 1
                wait_until(lambda: intake()["offered"] == n, 5, message="A's sample at the edge")
                after = snap()
                return bool(
                    after["streams"]["durable"]["buffer"]["blocked_appenders"] == 1
                    and after["intake"]["taken"] == before["taken"]
                    and after["intake"]["dropped"] == before["dropped"] + 1
                )

            while not flood_one_into_a_full_intake():  # until the thread waits on the full spool
                assert n < 2000, "the spool never filled"
            dropped = intake()["dropped"]
            for i in range(10):
                late.publish_cdr(cdr.encode_string(f"b:{i}"))
            wait_until(lambda: intake()["offered"] == n + 10, 5, message="B's ten samples at the edge")
            assert intake()["dropped"] == dropped + 10, intake()  # B's first ten: dropped at the intake
            wait_until(lambda: intake()["queued"] == 0, 20, message="the processing thread takes again")
            late.publish_cdr(cdr.encode_string("b:10"))  # seq 11: B's first sample taken
            late.seq += 5  # five samples lost on the way
            late.publish_cdr(cdr.encode_string("b:16"))  # seq 17

            def b_counts() -> dict[str, int]:
                counts: dict[str, int] = snap()["subscriptions"].get("/tb4_02/chatter", {})
                return counts

            wait_until(lambda: b_counts().get("received") == 2, 10, message="B's last two samples taken")
            counts = b_counts()
    assert (counts["gaps"], counts["missing"]) == (1, 5), counts
