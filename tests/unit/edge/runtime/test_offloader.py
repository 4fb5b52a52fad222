"""The uploader of claim-checked payloads: order per lane, retry when down, refusals, its bound."""

from __future__ import annotations

import queue
import threading

from fleetlink.common.objects import ObjectStoreError
from fleetlink.edge.claim_check import Claimed, ClaimJob, Upload
from fleetlink.edge.runtime.offloader import Offloader

WAIT_S = 5.0


class FakeStore:
    """Answers each put with the next outcome of ``outcomes`` (None: stored), then stores."""

    bucket = "b"

    def __init__(self, *outcomes: ObjectStoreError | None) -> None:
        self.outcomes = list(outcomes)
        self.puts: list[str] = []
        self.stored: dict[str, bytes] = {}
        self.gate = threading.Event()
        self.gate.set()

    def put(self, key: str, data: bytes, *, content_type: str, sha256_hex: str | None = None) -> object:
        self.gate.wait(WAIT_S)
        self.puts.append(key)
        outcome = self.outcomes.pop(0) if self.outcomes else None
        if outcome is not None:
            raise outcome
        self.stored[key] = data
        return None

    def url_of(self, key: str) -> str:
        return f"http://store/b/{key}"


def job(lane: str, name: str | None, size: int = 10) -> ClaimJob:
    upload = None if name is None else Upload(name, b"x" * size, "ab" * 32, "image/jpeg")
    return ClaimJob(lane, upload, context=name, size=size if upload else 0)


def offloader(store: FakeStore, **kwargs: object) -> tuple[Offloader, queue.Queue[Claimed]]:
    results: queue.Queue[Claimed] = queue.Queue()
    options: dict[str, object] = {"workers": 2, "backoff_min_s": 0.001, "backoff_max_s": 0.01, **kwargs}
    return Offloader(store, results.put, **options).start(), results  # type: ignore[arg-type]


def test_an_upload_comes_back_with_its_reference() -> None:
    store = FakeStore()
    up, results = offloader(store)
    assert up.submit(job("a", "k1")) is None
    done = results.get(timeout=WAIT_S)
    assert done.error is None
    assert done.ref is not None
    assert (done.ref.key, done.ref.url, done.ref.size) == ("k1", "http://store/b/k1", 10)
    assert store.stored["k1"] == b"x" * 10
    up.stop(1.0)


def test_an_inline_job_with_nothing_ahead_finishes_at_once_and_else_waits_its_turn() -> None:
    store = FakeStore()
    up, results = offloader(store)
    done = up.submit(job("a", None))
    assert done is not None
    assert done.ref is None
    assert done.error is None
    store.gate.clear()
    assert up.submit(job("a", "k1")) is None
    assert up.submit(job("a", None)) is None  # behind k1
    store.gate.set()
    order = [results.get(timeout=WAIT_S).job.context for _ in range(2)]
    assert order == ["k1", None]
    up.stop(1.0)


def test_a_store_that_is_down_is_tried_again_with_the_same_key_and_order_holds() -> None:
    down = ObjectStoreError("PUT: no answer", retriable=True)
    store = FakeStore(down, down, down)
    up, results = offloader(store)
    for name in ("k1", "k2", "k3"):
        assert up.submit(job("a", name)) is None
    order = [results.get(timeout=WAIT_S) for _ in range(3)]
    assert [c.job.context for c in order] == ["k1", "k2", "k3"]
    assert all(c.error is None for c in order)
    assert store.puts[:4] == ["k1", "k1", "k1", "k1"]
    snap = up.snapshot()
    assert (snap["retries"], snap["outages"], snap["uploaded"]) == (3, 1, 3)
    up.stop(1.0)


def test_a_refusal_comes_back_as_an_error_and_the_next_job_goes() -> None:
    store = FakeStore(ObjectStoreError("PUT: HTTP 403 AccessDenied", retriable=False, status=403))
    up, results = offloader(store)
    up.submit(job("a", "k1"))
    up.submit(job("a", "k2"))
    first, second = results.get(timeout=WAIT_S), results.get(timeout=WAIT_S)
    assert first.error is not None
    assert "HTTP 403" in first.error
    assert second.error is None
    assert second.ref is not None
    assert up.snapshot()["refused"] == 1
    up.stop(1.0)


def test_payloads_beyond_the_bound_are_refused_at_once_and_stop_hands_back_the_rest() -> None:
    store = FakeStore()
    store.gate.clear()
    up, results = offloader(store, max_pending_bytes=25)
    assert up.submit(job("a", "k1")) is None
    assert up.submit(job("a", "k2")) is None
    full = up.submit(job("a", "k3"))
    assert full is not None
    assert full.error is not None
    assert "objects.max_pending_bytes" in full.error
    assert up.snapshot()["full"] == 1
    up.stop(0.05)  # k1 is stuck in the store: both come back as errors
    store.gate.set()
    back = [results.get(timeout=WAIT_S) for _ in range(2)]
    assert {c.job.context for c in back} == {"k1", "k2"}
    assert all(c.error for c in back)
    assert up.snapshot()["abandoned"] == 2
    assert up.submit(job("a", "k4")) is not None  # closed
