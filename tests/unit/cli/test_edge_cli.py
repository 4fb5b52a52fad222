"""``fleetlink edge run`` before any socket: config errors, session defaults, no I/O in the constructor."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from fleetlink.cli import main
from fleetlink.common.zenoh_options import ZenohOptions
from fleetlink.edge.agent import EdgeAgent, edge_session_config
from fleetlink.edge.config import EdgeConfig
from fleetlink.edge.runtime.errors import RuntimeSetupError


def test_missing_config_file(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["edge", "run", "-c", str(tmp_path / "nope.yaml")]) == 1
    assert "config file not found" in capsys.readouterr().err


def test_bad_config_names_the_yaml_path(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    path = tmp_path / "edge.yaml"
    path.write_text("site: s1\nspool: {dir: /tmp/x}\ntopics:\n  dead_letter: 'no spaces allowed'\n")
    assert main(["edge", "run", "-c", str(path)]) == 1
    err = capsys.readouterr().err
    assert "topics.dead_letter (line 4)" in err
    assert not (tmp_path / "x").exists()


def test_edge_without_subcommand_prints_usage(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["edge"]) == 2
    assert "run" in capsys.readouterr().out


@pytest.mark.parametrize(
    ("options", "expected"),
    [
        (
            ZenohOptions(),
            {
                "mode": "peer",
                "connect/endpoints": ["tcp/127.0.0.1:7447"],
                "listen/endpoints": ["tcp/127.0.0.1:0"],
            },
        ),
        (
            ZenohOptions(mode="router", listen=("tcp/0.0.0.0:7447",)),
            {"mode": "router", "connect/endpoints": [], "listen/endpoints": ["tcp/0.0.0.0:7447"]},
        ),
        (
            ZenohOptions(mode="client", connect=("tcp/10.0.0.1:7447",)),
            {"mode": "client", "connect/endpoints": ["tcp/10.0.0.1:7447"]},
        ),
    ],
)
def test_session_defaults(options: ZenohOptions, expected: dict[str, object]) -> None:
    conf = edge_session_config(options)
    for key, value in expected.items():
        assert json.loads(conf.get_json(key)) == value, key
    assert json.loads(conf.get_json("timestamping/enabled")) is True


def test_a_router_mode_edge_takes_a_whole_site_of_sessions() -> None:
    router = edge_session_config(ZenohOptions(mode="router"))
    assert json.loads(router.get_json("transport/unicast/max_sessions")) == 20000
    assert json.loads(router.get_json("transport/shared_memory/enabled")) is False
    client = edge_session_config(ZenohOptions(mode="client"))
    assert json.loads(client.get_json("transport/unicast/max_sessions")) == 1000  # zenoh's own default


def config(tmp_path: Path, **extra: object) -> EdgeConfig:
    spool = {"dir": str(tmp_path / "spool")}
    return EdgeConfig.model_validate({"site": "s1", "edge_id": "e1", "spool": spool, **extra})


def test_constructor_touches_nothing(tmp_path: Path) -> None:
    agent = EdgeAgent(
        config(tmp_path, zenoh={"mode": "client", "connect": ["tcp/127.0.0.1:1"]}),
        ZenohOptions(connect=("tcp/127.0.0.1:2",)),
    )
    assert agent.zenoh_options.connect == ("tcp/127.0.0.1:2",)  # the command line wins
    assert agent.zenoh_options.mode == "client"
    assert not (tmp_path / "spool").exists()
    assert agent.snapshot()["running"] is False
    agent.stop()  # stopping what never started is harmless


def test_bad_message_path_fails_before_any_socket(tmp_path: Path) -> None:
    broken = tmp_path / "msgs" / "broken_msgs" / "msg"
    broken.mkdir(parents=True)
    (broken / "Bad.msg").write_text("this is not a field\n")
    agent = EdgeAgent(config(tmp_path, ros={"message_paths": [str(tmp_path / "msgs" / "broken_msgs")]}))
    with pytest.raises(RuntimeSetupError, match="message_paths"):
        agent.start()
    assert not (tmp_path / "spool").exists()


def test_multi_segment_robot_glob_is_refused_at_start(tmp_path: Path) -> None:
    agent = EdgeAgent(config(tmp_path, robot_types={"deep": {"match": "/fleet/tb4_*"}}))
    with pytest.raises(RuntimeSetupError, match=r"robot_types\.deep\.match"):
        agent.start()
    assert not (tmp_path / "spool").exists()
