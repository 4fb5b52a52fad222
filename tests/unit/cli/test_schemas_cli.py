"""``fleetlink schemas avro|hash|export`` run in-process through the real entry point."""

from __future__ import annotations

import json
from pathlib import Path

import avro.schema
import pytest

from fleetlink.cli import main
from tests.paths import IROBOT


@pytest.mark.parametrize(
    ("argv", "expected"),
    [
        (["std_msgs/msg/String"], "RIHS01_df668c740482bbd48fb39d76a70dfd4bd59db1288021743503259e948f6b1a18"),
        (["std_msgs/String", "--distro", "kilted"], "RIHS01_df668c74"),
        (["sensor_msgs/msg/Imu", "--distro", "humble"], "TypeHashNotSupported"),
        (["irobot_create_msgs/srv/EStop", "--msg-path", str(IROBOT)], "RIHS01_"),
    ],
)
def test_hash(argv: list[str], expected: str, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["schemas", "hash", *argv]) == 0
    out = capsys.readouterr().out.strip()
    assert out.startswith(expected)
    assert len(out) == (len("RIHS01_") + 64 if out.startswith("RIHS01_") else len(expected))


def test_avro_prints_the_schema(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["schemas", "avro", "irobot_create_msgs/msg/LightringLeds", "--msg-path", str(IROBOT)]) == 0
    schema = json.loads(capsys.readouterr().out)
    assert schema["name"] == "LightringLeds"
    assert schema["ros_type"] == "irobot_create_msgs/msg/LightringLeds"
    assert schema["ros_type_hash"].startswith("RIHS01_")


def test_export_writes_avsc_files(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert (
        main(
            ["schemas", "export", "--out", str(tmp_path / "out"), "sensor_msgs/msg/Imu", "nav_msgs/Odometry"]
        )
        == 0
    )
    files = sorted(p.name for p in (tmp_path / "out").iterdir())
    assert files == ["ros.nav_msgs.msg.Odometry.avsc", "ros.sensor_msgs.msg.Imu.avsc"]
    parsed = avro.schema.parse((tmp_path / "out" / files[1]).read_text())
    assert isinstance(parsed, avro.schema.RecordSchema)
    assert parsed.fullname == "ros.sensor_msgs.msg.Imu"
    assert str(tmp_path / "out" / files[0]) in capsys.readouterr().out


@pytest.mark.parametrize(
    ("argv", "words"),
    [
        (["schemas", "avro", "nope_msgs/msg/Missing"], "unknown ROS type 'nope_msgs/msg/Missing'"),
        (["schemas", "hash", "x/msg/Y", "--msg-path", "/nonexistent/pkg"], "not a directory"),
    ],
)
def test_errors_exit_non_zero(argv: list[str], words: str, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(argv) == 1
    assert words in capsys.readouterr().err
