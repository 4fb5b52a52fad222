"""``fleetlink ros sim``, ``graph``, ``echo``, ``pub`` and ``replay`` run as real processes."""

from __future__ import annotations

import itertools
import json
import os
import signal
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path

import pytest

from fleetlink.roswire.node import RosNode
from fleetlink.roswire.robot_watcher import RobotWatcher
from fleetlink.roswire.robots import RobotEvent, RobotEventKind, RobotType
from fleetlink.roswire.subscriber import RosSample
from tests.helpers import wait_until, zenoh_peer_config
from tests.paths import BAGS, IROBOT

CREATE3 = str(IROBOT)
_domains = itertools.count(501)


def fleetlink(*args: str) -> list[str]:
    return [sys.executable, "-m", "fleetlink", *args]


@pytest.fixture
def domain() -> int:
    return next(_domains)


@pytest.fixture
def sim(zenoh_router: str, domain: int) -> Iterator[subprocess.Popen[str]]:
    proc = subprocess.Popen(
        fleetlink(
            "ros",
            "sim",
            "--robots",
            "2",
            "--rate",
            "10",
            "--msg-path",
            CREATE3,
            "--duration",
            "60",
            "-e",
            zenoh_router,
            "--domain-id",
            str(domain),
        ),
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
        env={**os.environ, "PYTHONUNBUFFERED": "1"},
    )
    yield proc
    if proc.poll() is None:
        proc.kill()
    proc.wait(timeout=10)
    if proc.stdout:
        proc.stdout.close()


def test_ros_graph_json_reports_simulated_fleet_with_rates(
    zenoh_router: str, domain: int, sim: subprocess.Popen[str]
) -> None:
    assert sim.stdout is not None
    lines: list[str] = []
    while len(lines) < 10 and not (lines and lines[-1].startswith("simulating")):
        line = sim.stdout.readline()  # start-up log lines, then the banner (EOF if the sim died)
        if not line:
            break
        lines.append(line)
    assert lines[-1].startswith("simulating tb4_01, tb4_02 at 10 Hz"), lines
    result = subprocess.run(
        fleetlink(
            "ros",
            "graph",
            "--json",
            "--duration",
            "2",
            "--robot-type",
            "turtlebot4=/tb4_*",
            "-e",
            zenoh_router,
            "--domain-id",
            str(domain),
        ),
        capture_output=True,
        text=True,
        timeout=30,
        check=False,
    )
    assert result.returncode == 0, result.stderr
    report = json.loads(result.stdout)
    assert [(r["name"], r["type"]) for r in report["robots"]] == [
        ("tb4_01", "turtlebot4"),
        ("tb4_02", "turtlebot4"),
    ]
    assert {n["fqn"] for n in report["nodes"]} == {"/tb4_01/create3", "/tb4_02/create3"}
    topics = {t["name"]: t for t in report["topics"]}
    imu = topics["/tb4_01/imu"]
    assert imu["types"] == ["sensor_msgs/msg/Imu"]
    assert imu["publishers"][0]["qos"] == "best_effort, volatile, keep_last 5"
    assert imu["publishers"][0]["qos_wire"] == "2::,5:,:,:,,"
    assert imu["publishers"][0]["type_hash"] == (
        "RIHS01_7d9a00ff131080897a5ec7e26e315954b8eae3353c3f995c55faf71574000b5b"
    )
    assert 7.0 <= imu["rate_hz"] <= 12.0
    assert 0.3 <= topics["/tb4_02/battery_state"]["rate_hz"] <= 2.0
    assert topics["/tb4_01/cmd_lightring"]["subscribers"][0]["type"] == "irobot_create_msgs/msg/LightringLeds"
    assert report["malformed_tokens"] == 0


def test_killed_robot_process_is_deregistered_within_a_second(
    zenoh_router: str, domain: int, sim: subprocess.Popen[str]
) -> None:
    events: list[tuple[RobotEvent, float]] = []
    with (
        RosNode("fleetlink", domain_id=domain, config=zenoh_peer_config(zenoh_router)) as node,
        RobotWatcher(
            node,
            [RobotType("turtlebot4", "/tb4_*")],
            grace_s=0.1,
            tick_s=0.05,
            listeners=(lambda e: events.append((e, time.monotonic())),),
        ),
    ):
        wait_until(lambda: len(events) == 2, timeout=15, message="both simulated robots registered")
        killed = time.monotonic()
        os.kill(sim.pid, signal.SIGKILL)
        wait_until(lambda: len(events) == 4, timeout=5, message="both robots deregistered after kill -9")
    gone = events[2:]
    assert {e.robot for e, _ in gone} == {"tb4_01", "tb4_02"}
    assert all(e.kind is RobotEventKind.DEREGISTERED for e, _ in gone)
    assert max(t for _, t in gone) - killed < 1.0


def test_replay_command_publishes_a_bag_topic(zenoh_router: str, domain: int) -> None:
    received: list[RosSample] = []
    with RosNode("listener", domain_id=domain, config=zenoh_peer_config(zenoh_router)) as node:
        sub = node.create_subscriber(
            "/husky_01/fix", "sensor_msgs/msg/NavSatFix", received.append, type_hash=None, declare_token=False
        )
        result = subprocess.run(
            fleetlink(
                "ros",
                "replay",
                str(BAGS / "robot_localization_husky"),
                "--robot",
                "husky_01",
                "--fast",
                "--topic",
                "/fix",
                "--wait-subscribers",
                "10",
                "-e",
                zenoh_router,
                "--domain-id",
                str(domain),
            ),
            capture_output=True,
            text=True,
            timeout=60,
            check=False,
        )
        assert result.returncode == 0, result.stderr
        assert "published 989 messages on 1 topics" in result.stdout
        wait_until(lambda: len(received) == 989, timeout=10, message="989 NavSatFix samples")
        assert sub.stats.rejected == 0
        assert received[0].type_hash.startswith("RIHS01_")


def test_replay_command_reports_a_missing_bag(tmp_path: Path) -> None:
    result = subprocess.run(
        fleetlink("ros", "replay", str(tmp_path / "nope"), "--robot", "r", "--fast", "-e", "tcp/127.0.0.1:1"),
        capture_output=True,
        text=True,
        timeout=60,
        check=False,
    )
    assert result.returncode == 1
    assert "bag not found" in result.stderr


def test_sim_stdin_commands(zenoh_router: str, domain: int) -> None:
    result = subprocess.run(
        fleetlink(
            "ros",
            "sim",
            "--robots",
            "1",
            "--msg-path",
            CREATE3,
            "--stdin",
            "-e",
            zenoh_router,
            "--domain-id",
            str(domain),
        ),
        input="list\nfault tb4_01\nadd\nled tb4_02\nremove tb4_01\nheal tb4_09\njump\nlist\nquit\n",
        capture_output=True,
        text=True,
        timeout=60,
        check=False,
    )
    assert result.returncode == 0, result.stderr
    assert result.stdout.splitlines()[1:] == [
        "tb4_01",
        "tb4_01 picked up",
        "tb4_02 added",
        "tb4_02 light ring: green",
        "tb4_01 removed",
        "error: no robot named tb4_09",
        "unknown command 'jump' (fault R, heal R, add [R], remove R, led R, list, quit)",
        "tb4_02",
    ]


def test_sim_with_a_bad_msg_path_names_it() -> None:
    env = {k: v for k, v in os.environ.items() if k != "FLEETLINK_MSG_PATH"}
    result = subprocess.run(
        fleetlink(
            "ros",
            "sim",
            "--robots",
            "1",
            "--msg-path",
            "/nonexistent/pkg",
            "-m",
            "client",
            "-e",
            "tcp/127.0.0.1:1",
        ),
        capture_output=True,
        text=True,
        timeout=60,
        check=False,
        env=env,
    )
    assert result.returncode == 1
    assert "--msg-path /nonexistent/pkg: not a directory" in result.stderr


def run_cli(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(fleetlink(*args), capture_output=True, text=True, timeout=60, check=False)


def _banner(sim: subprocess.Popen[str]) -> None:
    assert sim.stdout is not None
    line = sim.stdout.readline()
    assert line.startswith("simulating"), line


def test_graph_text_is_quiet_and_readable(zenoh_router: str, domain: int, sim: subprocess.Popen[str]) -> None:
    _banner(sim)
    result = subprocess.run(
        fleetlink("ros", "graph", "--duration", "2", "-e", zenoh_router, "--domain-id", str(domain)),
        capture_output=True,
        text=True,
        timeout=30,
        check=False,
    )
    assert result.returncode == 0, result.stderr
    assert result.stderr == ""  # no log lines before (or after) the report without -v
    assert result.stdout.startswith(f"domain {domain}\n")
    imu = next(line for line in result.stdout.splitlines() if "/tb4_01/imu " in line)
    assert imu.endswith("[best_effort, volatile, keep_last 5]")


def test_echo_takes_type_and_qos_from_the_publisher(
    zenoh_router: str, domain: int, sim: subprocess.Popen[str]
) -> None:
    _banner(sim)
    at = ["-e", zenoh_router, "--domain-id", str(domain)]
    result = run_cli("ros", "echo", "/tb4_02/ir_intensity", "--once", "--timeout", "20", "--json", *at)
    assert result.returncode == 0, result.stderr
    (line,) = result.stdout.splitlines()
    message = json.loads(line)
    assert message["header"]["frame_id"] == "base_link"
    assert len(message["readings"]) == 7


def test_echo_gives_up_after_its_timeout(zenoh_router: str, domain: int) -> None:
    at = ["-e", zenoh_router, "--domain-id", str(domain)]
    result = run_cli("ros", "echo", "/nobody/here", "--once", "--timeout", "1", *at)
    assert result.returncode == 1
    assert "no publisher of /nobody/here within 1 s" in result.stderr


def test_pub_reaches_the_robot(zenoh_router: str, domain: int, sim: subprocess.Popen[str]) -> None:
    _banner(sim)
    red = "{override_system: true, leds: [" + ", ".join(["{red: 255}"] * 6) + "]}"
    at = ["-e", zenoh_router, "--domain-id", str(domain)]
    lightring = ["/tb4_01/cmd_lightring", "irobot_create_msgs/msg/LightringLeds"]
    result = run_cli("ros", "pub", *lightring, red, "--once", "--timeout", "20", *at)
    assert result.returncode == 0, result.stderr
    assert result.stdout.startswith("publishing #1 on /tb4_01/cmd_lightring: ")
    assert sim.stdout is not None
    assert sim.stdout.readline().strip() == "tb4_01 light ring: red"


def wait_banner(sim: subprocess.Popen[str]) -> None:
    """Read the simulator's output until its banner (its robots serve from then on)."""
    assert sim.stdout is not None
    for _ in range(20):
        line = sim.stdout.readline()
        if not line or line.startswith("simulating"):
            break
    assert line.startswith("simulating"), line


def test_ros_call_and_action_send_goal_reach_a_simulated_robot(
    zenoh_router: str, domain: int, sim: subprocess.Popen[str]
) -> None:
    """As ``ros2 service call`` and ``ros2 action send_goal``: the robot's e-stop and Dock over
    rmw_zenoh, their response and result printed as YAML; exit codes tell a missing service."""
    wait_banner(sim)
    where = ["-e", zenoh_router, "--domain-id", str(domain)]
    call = subprocess.run(
        fleetlink(
            "ros", "call", "/tb4_01/e_stop", "irobot_create_msgs/srv/EStop", "{e_stop_on: true}", *where
        ),
        capture_output=True,
        text=True,
        timeout=60,
        check=False,
    )
    assert call.returncode == 0, call.stderr
    assert "success: true" in call.stdout
    assert "e-stop on" in call.stdout
    goal = subprocess.run(
        fleetlink(
            "ros", "action", "send_goal", "/tb4_02/dock", "irobot_create_msgs/action/Dock", "-f", *where
        ),
        capture_output=True,
        text=True,
        timeout=60,
        check=False,
    )
    assert goal.returncode == 0, goal.stderr
    assert "is_docked: true" in goal.stdout
    assert "sees_dock" in goal.stdout  # the feedback, printed with -f
    missing = subprocess.run(
        fleetlink("ros", "call", "/tb4_09/e_stop", "irobot_create_msgs/srv/EStop", "--timeout", "2", *where),
        capture_output=True,
        text=True,
        timeout=60,
        check=False,
    )
    assert missing.returncode != 0
    assert missing.stderr.strip()
