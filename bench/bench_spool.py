"""The edge spool and the WAN batch format, measured on this machine.

Spool (300-byte records, a fresh spool in a temp dir on the same disk as the repo unless
``--dir`` says otherwise):

* ``append``: one ``Spool.append`` per record, for each fsync policy;
* ``append_many(100)``: the writer thread's path (it drains its queue in groups);
* ``read+ack``: the sender's path, batches of 500;
* ``writer+sender``: one thread appending, one reading and acking, at the same time, flat out
  and at a steady rate (append->read latency; the append time has millisecond resolution);
* ``reopen``: recovery time of a spool holding ``--reopen-mb`` of unacked records;
* ``--compare``: the same appends, read+ack and a kill -9 recovery with SQLite in WAL mode (per
  record and per group, ``synchronous=NORMAL`` and ``FULL``) and LMDB (``bench/spool_alternatives.py``),
  for the decision in docs/spool.md.

WAN batches: 500 records of the real Husky IMU bag (``/imu/data``), converted to Avro
single-object values, encoded with ``fleetlink.wire.encode_batch_payloads`` per codec.

Run: ``.venv/bin/python bench/bench_spool.py`` (``--quick`` for a short run).
"""

from __future__ import annotations

import argparse
import os
import shutil
import signal
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

from fleetlink.edge.spool import MemoryBuffer, Spool, SpoolOptions
from fleetlink.wire import Codec, Record, decode_batch, encode_batch_payloads, encode_payload

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from tests.paths import HUSKY  # noqa: E402


def rate(count: int, seconds: float) -> str:
    return f"{count / seconds:>12,.0f} /s"


def timed(fn: Callable[[], int], repeat: int) -> tuple[int, float]:
    """Best of ``repeat`` runs: (records, seconds)."""
    best: tuple[int, float] | None = None
    for _ in range(repeat):
        start = time.perf_counter()
        count = fn()
        elapsed = time.perf_counter() - start
        if best is None or count / elapsed > best[0] / best[1]:
            best = (count, elapsed)
    assert best is not None
    return best


def spool_options(fsync: str) -> SpoolOptions:
    return SpoolOptions(
        max_bytes=4 << 30,
        segment_bytes=64 << 20,
        fsync=fsync,  # type: ignore[arg-type]
        fsync_interval_ms=100,
        fsync_batch=1000,
    )


def bench_appends(base: Path, n: int, repeat: int) -> None:
    payload = os.urandom(300)
    print(f"spool appends, 300-byte records, {n:,} per run, best of {repeat}")
    for fsync, count in (("interval", n), ("batch", n), ("always", max(n // 200, 200))):

        def single(fsync: str = fsync, count: int = count) -> int:
            directory = Path(tempfile.mkdtemp(dir=base))
            with Spool(directory, spool_options(fsync)) as spool:
                for _ in range(count):
                    spool.append(payload)
            shutil.rmtree(directory)
            return count

        def grouped(fsync: str = fsync, count: int = count) -> int:
            directory = Path(tempfile.mkdtemp(dir=base))
            group = [payload] * 100
            with Spool(directory, spool_options(fsync)) as spool:
                for _ in range(count // 100):
                    spool.append_many(group)
            shutil.rmtree(directory)
            return count // 100 * 100

        done, seconds = timed(single, repeat)
        print(f"  fsync={fsync:<8} append          {rate(done, seconds)}")
        done, seconds = timed(grouped, repeat)
        print(f"  fsync={fsync:<8} append_many(100) {rate(done, seconds)}")
    memory = MemoryBuffer(max_records=n + 1, max_bytes=1 << 34)
    start = time.perf_counter()
    for _ in range(n):
        memory.append(payload)
    print(f"  memory buffer   append          {rate(n, time.perf_counter() - start)}")


def bench_sender(base: Path, n: int) -> None:
    payload = os.urandom(300)
    directory = Path(tempfile.mkdtemp(dir=base))
    with Spool(directory, spool_options("interval")) as spool:
        for _ in range(n // 100):
            spool.append_many([payload] * 100)
        start = time.perf_counter()
        done = 0
        while (batch := spool.read_unacked(500, 1 << 20)) is not None:
            done += len(batch.records)
            spool.ack(batch.first_seq)
        print(f"  read_unacked(500)+ack           {rate(done, time.perf_counter() - start)}")
    shutil.rmtree(directory)

    directory = Path(tempfile.mkdtemp(dir=base))
    with Spool(directory, spool_options("interval")) as spool:

        def flat_out(spool: Spool = spool) -> None:
            for _ in range(n // 100):
                spool.append_many([payload] * 100)

        thread = threading.Thread(target=flat_out)
        start = time.perf_counter()
        thread.start()
        received = pump(spool, n // 100 * 100, [])
        thread.join()
        print(f"  writer+sender threads, flat out {rate(received, time.perf_counter() - start)}")
    shutil.rmtree(directory)

    for per_second in (1_000, 20_000):
        directory = Path(tempfile.mkdtemp(dir=base))
        with Spool(directory, spool_options("interval")) as spool:
            total = per_second * 2
            group = max(1, per_second // 1000)  # one append_many per millisecond

            def paced(
                spool: Spool = spool, total: int = total, group: int = group, rate: int = per_second
            ) -> None:
                start = time.perf_counter()
                for i in range(total // group):
                    delay = start + i * group / rate - time.perf_counter()
                    if delay > 0:
                        time.sleep(delay)
                    spool.append_many([payload] * group)

            lags: list[float] = []
            thread = threading.Thread(target=paced)
            thread.start()
            pump(spool, total // group * group, lags)
            thread.join()
            lags.sort()
            print(
                f"  steady {per_second:>6,} records/s: append->read latency p50 "
                f"{lags[len(lags) // 2]:.2f} ms, p99 {lags[int(len(lags) * 0.99)]:.2f} ms"
            )
        shutil.rmtree(directory)


def pump(spool: Spool, expected: int, lags: list[float]) -> int:
    """The sender's loop: read, ack; ``lags`` gets each record's append->read time (ms)."""
    received = 0
    while received < expected:
        batch = spool.read_unacked(500, 1 << 20)
        if batch is None:
            time.sleep(0.0002)
            continue
        now = time.time_ns() / 1e6
        lags.extend(now - r.timestamp_ms for r in batch.records)
        received += len(batch.records)
        spool.ack(batch.first_seq)
    return received


def bench_reopen(base: Path, megabytes: int) -> None:
    payload = os.urandom(300)
    directory = Path(tempfile.mkdtemp(dir=base))
    count = megabytes * (1 << 20) // 328
    with Spool(directory, spool_options("interval")) as spool:
        for _ in range(count // 100):
            spool.append_many([payload] * 100)
    start = time.perf_counter()
    with Spool(directory, spool_options("interval")) as spool:
        elapsed = time.perf_counter() - start
        depth = spool.stats().depth
    print(
        f"  reopen {megabytes} MiB ({depth:,} unacked records): {elapsed * 1000:,.0f} ms "
        f"({depth / elapsed:,.0f} records/s scanned)"
    )
    shutil.rmtree(directory)


def imu_payloads(limit: int) -> tuple[list[bytes], dict[bytes, str]]:
    import json

    from rosbags.rosbag2 import Reader

    from fleetlink.schemas.codec import get_codec
    from fleetlink.schemas.single_object import fingerprint
    from fleetlink.schemas.typestore import load_typestore

    ts = load_typestore("humble", bags=[HUSKY])
    codec = get_codec(ts, "sensor_msgs/msg/Imu", "humble")
    fp = fingerprint(codec.schema)
    payloads = []
    with Reader(HUSKY) as reader:
        connections = [c for c in reader.connections if c.topic == "/imu/data"]
        for _, stamp, raw in reader.messages(connections=connections):
            value = b"\xc3\x01" + fp + codec.cdr_to_avro(raw)
            headers = (
                ("ros.topic", b"/husky_01/imu/data"),
                ("ros.type", b"sensor_msgs/msg/Imu"),
                ("ros.type_hash", codec.type_hash.encode()),
                ("site", b"warehouse-a"),
            )
            record = Record(
                kafka_topic="fleet.imu",
                key=b"husky_01",
                value=value,
                headers=headers,
                timestamp_ms=stamp // 1_000_000,
            )
            payloads.append(encode_payload(record))
            if len(payloads) >= limit:
                break
    return payloads, {fp: json.dumps(codec.schema)}


def bench_wan(repeat: int) -> None:
    payloads, schemas = imu_payloads(5000)
    size = sum(len(p) for p in payloads[:500])
    print(f"WAN batches: 500 real Imu records per batch ({size / 500:.0f} bytes each as spooled)")
    codecs: list[Codec] = ["none", "zlib", "zstd"]
    for codec in codecs:
        batches = [list(enumerate(payloads[i : i + 500], start=i + 1)) for i in range(0, len(payloads), 500)]

        def encode(codec: Codec = codec, batches: list[list[tuple[int, bytes]]] = batches) -> int:
            for items in batches:
                encode_batch_payloads(
                    site="warehouse-a",
                    edge_id="edge-1",
                    stream="durable",
                    items=items,
                    schemas=schemas,
                    codec=codec,
                )
            return sum(len(b) for b in batches)

        encoded = [
            encode_batch_payloads(
                site="warehouse-a", edge_id="edge-1", stream="durable", items=b, schemas=schemas, codec=codec
            )
            for b in batches
        ]

        def decode(encoded: list[bytes] = encoded) -> int:
            return sum(len(decode_batch(data).records) for data in encoded)

        done, enc_s = timed(encode, repeat)
        dec_done, dec_s = timed(decode, repeat)
        wire = sum(len(e) for e in encoded) / len(encoded)
        print(
            f"  {codec:<5} {wire:>9,.0f} bytes/batch ({wire / 500:5.0f} per record)  "
            f"encode {rate(done, enc_s)}  decode {rate(dec_done, dec_s)}"
        )


def bench_alternatives(base: Path, n: int, repeat: int) -> None:
    """Per store: ``append`` (one record, one commit), ``append_group`` of a ready group of 100
    records (what the edge's data plane hands the spool), and read+ack of batches of 500."""
    from bench.spool_alternatives import HAVE_LMDB, LmdbGroups, SpoolStore, SqliteGroups, SqliteRows
    from fleetlink.wire.groups import encode_group

    payload = os.urandom(300)
    payloads = [payload] * 100
    group = encode_group(payloads)
    makers: list[tuple[Callable[[Path], Any], bool]] = [
        (SpoolStore, False),
        (lambda d: SqliteRows(d, "NORMAL"), False),
        (lambda d: SqliteRows(d, "FULL"), True),
        (lambda d: SqliteGroups(d, "NORMAL"), False),
        (lambda d: SqliteGroups(d, "FULL"), True),
    ]
    if HAVE_LMDB:
        makers += [(lambda d: LmdbGroups(d, sync=False), False), (lambda d: LmdbGroups(d, sync=True), True)]
    else:
        print("  (lmdb is not installed: pip install lmdb)")
    print(
        f"alternatives: 300-byte records, {n:,} per run (fsync per commit: {max(n // 200, 200):,}), "
        f"best of {repeat}; records/s"
    )
    print(f"  {'store':<40} {'append':>12}    {'append_group(100)':>17}    {'read+ack 500':>14}")
    for make, synced in makers:
        count = max(n // 200, 200) if synced else n

        def run(step: Callable[[Any], int], make: Callable[[Path], Any] = make) -> tuple[str, int]:
            directory = Path(tempfile.mkdtemp(dir=base))
            store = make(directory)
            try:
                return store.name, step(store)
            finally:
                store.close()
                shutil.rmtree(directory)

        def single(count: int = count) -> int:
            def step(store: Any) -> int:
                for _ in range(count):
                    store.append(payload)
                return count

            return run(step)[1]

        def grouped(count: int = count) -> int:
            def step(store: Any) -> int:
                if isinstance(store, SqliteRows) and not isinstance(store, SqliteGroups):
                    for _ in range(count // 100):
                        store.append_many(payloads)  # a row per record: the group is unpacked
                else:
                    for _ in range(count // 100):
                        store.append_group(group, 100)
                return count // 100 * 100

            return run(step)[1]

        def read_ack(count: int = count) -> tuple[str, int]:
            def step(store: Any) -> int:
                for _ in range(count // 100):
                    store.append_many(payloads)
                start = time.perf_counter()
                done = 0
                while groups := store.read_groups(500):
                    done += sum(g[1] for g in groups)
                    store.ack(groups[-1][0] + groups[-1][1] - 1)
                return int(done / (time.perf_counter() - start))

            return run(step)

        s_done, s_s = timed(single, repeat)
        g_done, g_s = timed(grouped, repeat)
        name, reads = read_ack()
        print(f"  {name:<40} {rate(s_done, s_s)}  {rate(g_done, g_s)}  {reads:>12,} /s")
    print("kill -9 while appending groups of 10 flat out (2 s), then reopen")
    kinds = ["spool", "sqlite-rows", "sqlite-groups"] + (["lmdb"] if HAVE_LMDB else [])
    for kind in kinds:
        recovery(base, kind)


def recovery(base: Path, kind: str) -> None:
    from bench.spool_alternatives import open_store

    directory = Path(tempfile.mkdtemp(dir=base))
    child = subprocess.Popen(
        [sys.executable, "-m", "bench.spool_alternatives", kind, str(directory)],
        cwd=ROOT,
        stdout=subprocess.PIPE,
        text=True,
    )
    taken: list[int] = []
    reader = threading.Thread(target=lambda: taken.extend(int(line) for line in child.stdout or ()))
    reader.start()
    time.sleep(2.0)
    child.send_signal(signal.SIGKILL)
    child.wait()
    reader.join()
    size = sum(p.stat().st_size for p in directory.rglob("*") if p.is_file())
    start = time.perf_counter()
    store: Any = open_store(kind, directory)
    held = store.count()
    opened = time.perf_counter() - start
    seqs = store.seqs()
    store.close()
    last = taken[-1] if taken else 0
    lost = sum(1 for s in range(1, last + 1) if s not in seqs)
    print(
        f"  {kind:<14} {last:>9,} records taken, {size / (1 << 20):6.1f} MiB on disk; reopen + count "
        f"{opened * 1000:7.1f} ms; {held:,} held, {lost} taken and lost"
    )
    shutil.rmtree(directory)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0] if __doc__ else None)
    parser.add_argument("--dir", type=Path, default=ROOT / ".cache", help="where temp spools go")
    parser.add_argument("--records", type=int, default=200_000)
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--reopen-mb", type=int, default=256)
    parser.add_argument("--quick", action="store_true", help="small sizes, one run each")
    parser.add_argument("--compare", action="store_true", help="only the SQLite / LMDB comparison")
    args = parser.parse_args()
    if args.quick:
        args.records, args.repeat, args.reopen_mb = 20_000, 1, 16
    args.dir.mkdir(parents=True, exist_ok=True)
    print(f"machine: {os.cpu_count()} CPUs; spool directory under {args.dir}")
    if args.compare:
        bench_appends(args.dir, args.records, args.repeat)
        bench_alternatives(args.dir, args.records, args.repeat)
        return
    bench_appends(args.dir, args.records, args.repeat)
    print("spool sender side")
    bench_sender(args.dir, args.records)
    bench_reopen(args.dir, args.reopen_mb)
    bench_wan(args.repeat)


if __name__ == "__main__":
    main()
