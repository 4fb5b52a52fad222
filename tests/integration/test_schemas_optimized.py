"""Bad input gets the same errors under ``python -O`` (no assert is used for validation)."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]

SCRIPT = r"""
import json, struct
from fleetlink.schemas.codec import get_codec
from fleetlink.schemas.errors import SchemaError
from fleetlink.schemas.typestore import load_typestore

ts = load_typestore("jazzy")
cases = [
    ("std_msgs/msg/String", "cdr", b""),
    ("std_msgs/msg/String", "cdr", b"\x01\x01\x00\x00\x02\x00\x00\x00a\x00"),
    ("std_msgs/msg/String", "cdr", b"\x00\x01\x00\x00\x09\x00\x00\x00ab"),
    ("std_msgs/msg/String", "cdr", b"\x00\x01\x00\x00\x03\x00\x00\x00\xff\xfe\x00"),
    ("std_msgs/msg/Bool", "cdr", b"\x00\x01\x00\x00\x05"),
    ("std_msgs/msg/UInt64", "cdr", b"\x00\x01\x00\x00" + struct.pack("<Q", 2**64 - 1)),
    ("sensor_msgs/msg/Imu", "cdr", b"\x00\x01\x00\x00" + bytes(30)),
    ("std_msgs/msg/Int8", "avro", b"\xfe\x03"),
    ("std_msgs/msg/String", "avro", b"\x08ab"),
    ("geometry_msgs/msg/Twist", "avro", bytes(20)),
]
out = []
for typename, direction, data in cases:
    codec = get_codec(ts, typename, "jazzy")
    func = codec.cdr_to_avro if direction == "cdr" else codec.avro_to_cdr
    try:
        func(data)
        out.append(["no error"])
    except SchemaError as exc:
        out.append([type(exc).__name__, exc.typename, exc.offset, exc.reason])
print(json.dumps(out))
"""


def _run(*flags: str) -> list[list[object]]:
    result = subprocess.run(
        [sys.executable, *flags, "-c", SCRIPT],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=60,
        check=False,
    )
    assert result.returncode == 0, result.stderr
    answer: list[list[object]] = json.loads(result.stdout)
    return answer


def test_same_errors_with_and_without_optimisation() -> None:
    plain, optimised = _run(), _run("-O")
    assert optimised == plain
    names = [row[0] for row in plain]
    assert "no error" not in names
    assert names.count("ValueRangeError") == 2  # uint64 overflow, int8 out of range
    assert {row[1] for row in plain} >= {"std_msgs/msg/String", "sensor_msgs/msg/Imu"}
