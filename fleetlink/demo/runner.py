"""Start everything the demo needs, play the scenario, tell what happens, stop it all.

Kafka and the registry (unless given), two Zenoh routers (the cloud's and the site's), the
uplink, the edge agent and the repeater as their own processes (``fleetlink ... run``), the
fault-detection app and the simulated robots in this process, so their events can be told as
they happen.
"""

from __future__ import annotations

import contextlib
import json
import secrets
import shutil
import sys
import threading
import time
import uuid
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal, TextIO

import yaml

from fleetlink.common.command_keys import write_command_key
from fleetlink.common.durations import parse_duration_ms
from fleetlink.common.errors import FleetlinkError
from fleetlink.demo.configs import (
    COMMAND_TOPIC,
    REGISTRATIONS_TOPIC,
    SENSOR_TOPICS,
    DemoPlaces,
    edge_config,
    repeater_config,
    uplink_config,
)
from fleetlink.demo.story import Story, led_colour
from fleetlink.demo.supervision import run_restarting
from fleetlink.demo.watch import LogFollower, TopicWatcher, app_has_committed
from fleetlink.localstack.process import ServerProcess, free_port, log_tail, port_in_use
from fleetlink.localstack.registry import registry_url_lines
from fleetlink.localstack.stack import LocalStack
from fleetlink.localstack.zenoh_router import ZenohRouter

APP_ATTEMPTS = 3
"""Runs of the Python fault-detection app before the demo gives up on it (``supervision``)."""


class DemoError(FleetlinkError):
    """The demo could not reach a step; the message says which and where its logs are."""


@dataclass
class DemoOptions:
    """How to run the demo: its folder, robots and sensor rate, the app's window, an existing Kafka."""

    workdir: Path = Path("var/demo")
    robots: int = 3
    rate_hz: float = 10.0
    window: str = "2s"
    bootstrap: str | None = None
    registry_url: str | None = None
    keep_running: bool = False
    duration_s: float | None = None
    step_timeout_s: float = 90.0
    app: Literal["python", "java"] = "python"
    usual_ports: bool = True
    """Serve the consoles and metrics on the docs' ports (8480, 8490, 9464) where free; False: on
    free ports only, for a demo started beside other services that may take those ports."""
    out: TextIO = field(default=sys.stdout)


class Demo:
    """One run of the demo: starts every part, plays the scenario while telling it, stops it all."""

    def __init__(self, options: DemoOptions) -> None:
        self.o = options
        self.story = Story(started_at=time.monotonic())
        self._stop = threading.Event()
        self._lock = threading.Lock()
        self._exit = contextlib.ExitStack()
        self._since_ms = time.time_ns() // 1_000_000 - 1_000
        self._app_group = f"fleetlink-demo-{uuid.uuid4().hex[:8]}"
        self._closing = threading.Event()
        self.token = secrets.token_urlsafe(12)
        """The access token of the consoles and admin APIs of this run."""

    # -- telling ---------------------------------------------------------------------------

    def say(self, text: str, *, closing: bool = False) -> None:
        """Tell one line; once the demo is stopping, only its closing lines (output stays in order)."""
        with self._lock:
            if self._closing.is_set() and not closing:
                return
            print(f"{self.story.at(time.monotonic())} {text}", file=self.o.out, flush=True)

    def stop(self) -> None:
        """Ask the run to stop: a step under way gives up, and ``--keep-running`` ends."""
        self._stop.set()

    # -- the whole run ---------------------------------------------------------------------

    def run(self) -> dict[str, Any]:
        """Start everything, play the scenario, stop it all; returns the summary (also in ``summary.json``).

        Raises ``DemoError`` when a step is not reached in time or the run is interrupted.
        """
        with self._exit:
            places = self._start_infrastructure()
            self._start_services(places)
            self._start_watchers(places)
            self._start_app(places)
            summary = self._scenario(places)
            path = self.o.workdir / "summary.json"
            path.write_text(json.dumps(summary, indent=2))
            self.say(f"summary written to {path}")
            if self.o.keep_running and not self._stop.is_set():
                self.say("the loop is closed; still running — Ctrl-C stops everything")
                self._wait(self.o.duration_s)
            with self._lock:
                self._closing.set()  # from here on only the closing lines are told
            self.say("stopping everything the demo started ...", closing=True)
        self.say("stopped", closing=True)
        return summary

    def _start_infrastructure(self) -> DemoPlaces:
        work = self.o.workdir
        if work.exists():
            shutil.rmtree(work)
        (work / "logs").mkdir(parents=True)
        if self.o.bootstrap and self.o.registry_url:
            bootstrap, registry = self.o.bootstrap, self.o.registry_url
            self.say(f"using Kafka {bootstrap} and registry {registry}")
        else:
            self.say("starting Apache Kafka (KRaft) and Apicurio Registry (first run fetches their jars) ...")
            stack = LocalStack(work / "stack")
            info = stack.start()
            self._exit.callback(stack.stop)
            bootstrap, registry = info.bootstrap, info.registry_url
            self.say(
                f"Kafka up in {info.kafka_seconds:.1f} s at {bootstrap}; "
                f"registry up in {info.registry_seconds:.1f} s at {registry}"
            )
        for line in registry_url_lines(registry):
            self.say(f"registry {line}")
        cloud = self._exit.enter_context(ZenohRouter())
        site = self._exit.enter_context(ZenohRouter(connect=(cloud.endpoint,)))
        self.say(f"Zenoh routers: cloud {cloud.endpoint}, site warehouse-a {site.endpoint} (linked)")
        # the Create 3 definitions ship with fleetlink: no message paths needed
        return DemoPlaces(
            bootstrap,
            registry,
            cloud.endpoint,
            site.endpoint,
            work,
            (),
            edge_admin=self._listen(8480),
            uplink_metrics=self._listen(9464),
            fleet_console=self._listen(8490),
        )

    def _listen(self, preferred: int) -> str:
        """127.0.0.1 and the port people expect (the docs' 8480, 8490, 9464), or a free one."""
        usual = self.o.usual_ports and not port_in_use(preferred)
        return f"127.0.0.1:{preferred if usual else free_port()}"

    def _process(self, name: str, argv: list[str], ready: Callable[[], bool]) -> None:
        self._start_process(name, [sys.executable, "-m", "fleetlink", *argv], ready)

    def _start_process(self, name: str, argv: list[str], ready: Callable[[], bool]) -> None:
        log = self.o.workdir / "logs" / f"{name}.log"
        proc = ServerProcess(
            name=name,
            argv=argv,
            log_path=log,
            pid_path=self.o.workdir / f"{name}.pid",
            ready=ready,
            env={"FLEETLINK_ADMIN_TOKEN": self.token},
        )
        took = proc.start(timeout=self.o.step_timeout_s)
        self._exit.callback(proc.stop)
        self.say(f"{name} running ({took:.1f} s; log: {log})")

    def _start_services(self, places: DemoPlaces) -> None:
        work = self.o.workdir
        write_command_key(places.keys)  # the uplink signs commands, the repeater checks them
        files = {}
        for name, config in (
            ("uplink", uplink_config(places)),
            ("edge", edge_config(places)),
            ("repeater", repeater_config(places)),
        ):
            files[name] = work / f"{name}.yaml"
            files[name].write_text(yaml.safe_dump(config, sort_keys=False))
        logs = work / "logs"
        self._process(
            "uplink",
            ["uplink", "run", "-c", str(files["uplink"])],
            lambda: "uplink running" in _read(logs / "uplink.log"),
        )
        stats = work / "edge-stats.json"
        self._process(
            "edge", ["edge", "run", "-c", str(files["edge"]), "--stats-file", str(stats)], stats.exists
        )
        self._process(
            "repeater",
            ["repeater", "run", "-c", str(files["repeater"])],
            lambda: "running for site" in _read(logs / "repeater.log"),
        )
        self.say(
            f"web console: http://{places.fleet_console}/console/ (the fleet), "
            f"http://{places.edge_admin}/console/ (site warehouse-a); sign in with token {self.token}"
        )
        self.say(
            f"metrics: http://{places.uplink_metrics}/metrics (uplink), "
            f"http://{places.edge_admin}/metrics (edge); health: /health on both"
        )

    def _start_watchers(self, places: DemoPlaces) -> None:
        def on_registration(_topic: str, key: bytes | None, value: dict[str, Any] | None, _m: Any) -> None:
            robot = (key or b"").decode(errors="replace")
            event = (value or {}).get("event", "?")
            if event == "registered" and robot not in self.story.registered:
                self.story.registered[robot] = time.monotonic()
                self.say(
                    f"robot {robot} registered ({(value or {}).get('robot_type', '?')}): "
                    "its mappings are live"
                )
            elif event == "deregistered":
                self.say(f"robot {robot} deregistered ({(value or {}).get('reason', '')})")

        def on_command(_topic: str, key: bytes | None, value: dict[str, Any] | None, _m: Any) -> None:
            robot = (key or b"").decode(errors="replace")
            colour = led_colour(value)
            self.story.on_command(robot, colour)
            self.say(f"command in Kafka  {COMMAND_TOPIC}  {robot} ← light ring {colour}")

        for topics, decode, handler in (
            ([REGISTRATIONS_TOPIC], True, on_registration),
            ([COMMAND_TOPIC], True, on_command),
        ):
            watcher = TopicWatcher(
                places.bootstrap,
                places.registry_url,
                topics,
                decode=decode,
                on_record=handler,
                since_ms=self._since_ms,
            ).start()
            self._exit.callback(watcher.stop)
        self._flow = TopicWatcher(
            places.bootstrap,
            places.registry_url,
            SENSOR_TOPICS,
            decode=False,
            on_record=lambda *_: None,
            since_ms=self._since_ms,
        ).start()
        self._exit.callback(self._flow.stop)
        ticker = threading.Thread(target=self._tell_rates, name="demo-rates", daemon=True)
        ticker.start()

    def _tell_rates(self) -> None:
        last: dict[str, int] = {}
        every = 10.0
        while not self._closing.wait(every) and not self._stop.is_set():
            counts = dict(self._flow.counts)
            rates = {t: (counts.get(t, 0) - last.get(t, 0)) / every for t in SENSOR_TOPICS}
            last = counts
            if any(rates.values()):
                self.say("records/s in Kafka: " + ", ".join(f"{t} {r:.0f}" for t, r in rates.items()))

    def _start_app(self, places: DemoPlaces) -> None:
        if self.o.app == "java":
            self._start_java_app(places)
            return
        from fleetlink.examples.fault_detection.app import run as run_app
        from fleetlink.examples.fault_detection.rules import LightCommand
        from fleetlink.examples.fault_detection.settings import FaultDetectionSettings, parse_duration_ms

        settings = FaultDetectionSettings(
            bootstrap=places.bootstrap,
            registry_url=places.registry_url,
            window=parse_duration_ms(self.o.window) / 1000,
            state_dir=places.workdir / "app-state",
            # a fresh consumer group per run: on a shared Kafka, earlier runs' records are not replayed
            group=self._app_group,
            offset_reset="latest",
            msg_paths=places.msg_paths,
        )
        stop = threading.Event()

        def decided(command: LightCommand) -> None:
            state = getattr(command.state, "value", command.state)
            self.say(f"fault detection: {command.robot} is now {state} (every event in its window agreed)")

        def restarted(error: BaseException, attempt: int) -> None:
            self.say(f"fault-detection app stopped on an error ({error!r}); starting it again ({attempt})")

        def supervised() -> None:
            run_restarting(
                lambda: run_app(settings, stop, decided),
                attempts=APP_ATTEMPTS,
                stop=stop,
                on_restart=restarted,
            )

        thread = threading.Thread(target=supervised, name="fault-app", daemon=True)
        thread.start()

        def stop_app() -> None:
            stop.set()
            thread.join(15)

        self._exit.callback(stop_app)
        self.say(f"fault-detection app running (Quix Streams; sliding window {self.o.window} per robot)")

    def _start_java_app(self, places: DemoPlaces) -> None:
        from fleetlink.examples import kafka_streams
        from fleetlink.localstack.java import find_java
        from fleetlink.schemas.registry_urls import apicurio_native_url

        native = apicurio_native_url(places.registry_url)
        if native is None:
            raise DemoError(
                f"--app java needs an Apicurio Registry (its Java serde speaks the native API); "
                f"{places.registry_url} is not an Apicurio ccompat URL (…/apis/ccompat/v7)"
            )
        if kafka_streams.needs_build():
            self.say("building the Kafka Streams app with Maven (the first build downloads its jars) ...")
            took = kafka_streams.build(tests=False)
            self.say(f"built {kafka_streams.JAR.name} in {took:.1f} s")
        argv = kafka_streams.command(
            find_java(17, "the Kafka Streams app"),
            bootstrap=places.bootstrap,
            registry_native_url=native,
            window_ms=parse_duration_ms(self.o.window),
            group=self._app_group,
            state_dir=places.workdir / "app-state",
        )
        log = self.o.workdir / "logs" / "fault-detection.log"

        def decided(line: str) -> None:
            change = kafka_streams.parse_state_change(line)
            if change is not None:
                robot, state = change.robot, change.after
                self.say(f"fault detection: {robot} is now {state} (every event in its window agreed)")

        self._start_process("fault-detection", argv, lambda: kafka_streams.READY_LINE in _read(log))
        follower = LogFollower(log, decided).start()
        self._exit.callback(follower.stop)
        self.say(f"fault-detection app: Kafka Streams (Java), sliding window {self.o.window} per robot")

    # -- the scenario ----------------------------------------------------------------------

    def _scenario(self, places: DemoPlaces) -> dict[str, Any]:
        from fleetlink.common.zenoh_options import ZenohOptions
        from fleetlink.roswire.session import ros_session_config
        from fleetlink.roswire.sim.fleet import Fleet
        from fleetlink.schemas.typestore import load_typestore

        ts = load_typestore("jazzy", list(places.msg_paths))

        def on_led(robot: str, state: Any) -> None:
            colour = str(state.name).lower()
            if self.story.on_led(robot, colour, time.monotonic()):
                self.say(f"robot {robot} light ring is now {colour.upper()}")

        config = ros_session_config(ZenohOptions(mode="client", connect=(places.site_router,)))
        fleet = self._exit.enter_context(
            Fleet(config, ts, robots=self.o.robots, rate=self.o.rate_hz, on_led=on_led)
        )
        names = fleet.names()
        self.say(
            f"simulated TurtleBot 4 fleet up: {', '.join(names)} (IR, hazards, kidnap, odom, imu, "
            f"battery at {self.o.rate_hz:g} Hz; each listens on cmd_lightring)"
        )
        self._until(lambda: set(names) <= set(self.story.registered), "every robot registered")
        self._until(
            lambda: all(self._flow.counts.get(t, 0) > 0 for t in SENSOR_TOPICS),
            "records flowing into every sensor topic",
        )
        self.say("sensor data is flowing: " + ", ".join(SENSOR_TOPICS))
        # judge a fault only once the app has whole windows of healthy events behind it
        self._until(
            lambda: app_has_committed(places.bootstrap, self._app_group, SENSOR_TOPICS),
            "the fault-detection app consuming every sensor topic",
        )
        self._wait(parse_duration_ms(self.o.window) / 1000 + 1.0)

        healthy, faulted = names[0], names[1 % len(names)]
        self.say(f"glitch: one spurious 'picked up' reading on {healthy} (shorter than the window)")
        fleet.inject_fault(healthy)
        self._wait(0.15)
        fleet.heal(healthy)

        joined = fleet.add_robot()
        self.say(f"robot {joined} joins the site")
        self._until(lambda: joined in self.story.registered, f"{joined} registered")
        self._wait(3.0)

        self.say(f"FAULT: {faulted} is picked up (kidnap status true, IR readings saturated)")
        self.story.faults[faulted] = time.monotonic()
        fleet.inject_fault(faulted)
        self._until(lambda: self.story.led_now(faulted) == "red", f"{faulted} light ring red")
        self.say(f"loop closed: fault → red light ring in {self.story.latencies[f'{faulted}:red']:.1f} s")
        self._wait(3.0)
        self.say(f"HEAL: {faulted} is put down")
        self.story.heals[faulted] = time.monotonic()
        fleet.heal(faulted)
        self._until(lambda: self.story.led_now(faulted) == "green", f"{faulted} light ring green")
        took = self.story.latencies[f"{faulted}:green"]
        self.say(f"recovered: put down → green light ring in {took:.1f} s")
        self._wait(5.0)  # let any unexpected command show up before judging
        others = [n for n in fleet.names() if n != faulted]
        summary = self.story.summary(faulted, others, joined)
        self.say("summary: " + json.dumps(summary))
        return summary

    def _until(self, predicate: Callable[[], bool], what: str) -> None:
        deadline = time.monotonic() + self.o.step_timeout_s
        while not predicate():
            if self._stop.is_set():
                raise DemoError(f"interrupted while waiting for: {what}")
            if time.monotonic() > deadline:
                logs = self.o.workdir / "logs"
                tails = "\n".join(f"--- {p.name}\n{log_tail(p, 8)}" for p in sorted(logs.glob("*.log")))
                raise DemoError(f"gave up after {self.o.step_timeout_s:.0f} s waiting for: {what}\n{tails}")
            self._stop.wait(0.1)

    def _wait(self, seconds: float | None) -> None:
        self._stop.wait(seconds)


def _read(path: Path) -> str:
    try:
        return path.read_text(errors="replace")
    except OSError:
        return ""


@contextlib.contextmanager
def interrupted_on_sigint(demo: Demo) -> Iterator[None]:
    """Within the block, SIGINT and SIGTERM stop ``demo`` instead of the process."""
    import signal

    previous = {s: signal.signal(s, lambda *_: demo.stop()) for s in (signal.SIGINT, signal.SIGTERM)}
    try:
        yield
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, handler)
