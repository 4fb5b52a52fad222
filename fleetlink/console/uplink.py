"""``UplinkConsole``: the fleet-wide console the uplink serves (every site, over Zenoh).

    console = UplinkConsole(settings, session=session, router=lambda: uplink.commands).start()
    console.url            # http://127.0.0.1:8490 ; pages under /console/
    console.stop()

Sites are found and changed through their Zenoh admin space (``ZenohSites``); what Kafka
acknowledged comes from every uplink's delivery figures (``fleetlink/<site>/delivery/<uplink>``,
this one's included); command status from its command router (``command_view``).
"""

from __future__ import annotations

import functools
import io
import json
import logging
from collections.abc import Callable
from types import TracebackType
from typing import TYPE_CHECKING, Any

import fastavro
import zenoh
from fastapi import FastAPI
from fastapi.responses import RedirectResponse
from pydantic import SecretStr

from fleetlink.common.console_config import ConsoleSection
from fleetlink.common.exposure import check_exposure
from fleetlink.common.metrics import HttpServer
from fleetlink.console.app import Operations, create_console_app
from fleetlink.console.audit import Audit, KafkaAudit, MemoryAudit
from fleetlink.console.auth import load_console_token
from fleetlink.console.errors import ConsoleError
from fleetlink.console.history import History
from fleetlink.console.kafka_ops import KafkaCommands, KafkaDeadLetters, StatusBook
from fleetlink.console.kafka_tail import KafkaTail
from fleetlink.console.remote import ZenohSites
from fleetlink.console.sampler import HistorySampler
from fleetlink.console.users import load_users
from fleetlink.schemas.avro_schema import avro_schema
from fleetlink.schemas.bundled import bundled_message_paths
from fleetlink.schemas.errors import RegistryError
from fleetlink.schemas.registry import SchemaRegistry
from fleetlink.schemas.typestore import load_typestore
from fleetlink.uplink.commands.status_records import STATUS_SCHEMA

if TYPE_CHECKING:
    from rosbags.typesys.store import Typestore

    from fleetlink.uplink.commands.router import CommandRouter
    from fleetlink.uplink.config import UplinkConfig
    from fleetlink.uplink.service import Uplink

log = logging.getLogger(__name__)

NO_COMMANDS = "not available on this process: this uplink routes no commands (no command mappings configured)"


def command_view(router: CommandRouter | None) -> dict[str, Any]:
    """The command router's counters for the console (``available: false`` without one)."""
    if router is None:
        return {"available": False, "reason": NO_COMMANDS}
    stats = router.stats
    with stats.lock:
        counts = {
            "records": stats.records,
            "forwards": stats.forwards,
            "settled": stats.settled,
            "dead_lettered": stats.dead_lettered,
            "expired_before_forward": stats.expired_before_forward,
            "expired_unacknowledged": stats.expired_unacknowledged,
            "results": dict(stats.results),
        }
    mappings = [{"name": m.name, "from": m.from_, "to": m.to} for m in router.config.commands]
    return {
        "available": True,
        **counts,
        "in_flight": router.in_flight(),
        "status_records_written": router.status_writer.written,
        "status_batches": router.intake.batches,
        "heartbeats": router.intake.heartbeats,
        "robots_known": len(router.directory),
        "sites": router.directory.sites(),
        "mappings": mappings,
    }


class UplinkConsole:
    """The fleet console the uplink serves on ``console.listen``: every site over Zenoh, and the
    audit topic, dead letters and commands through Kafka when it has the uplink's config."""

    def __init__(
        self,
        settings: ConsoleSection,
        *,
        session: zenoh.Session,
        router: Callable[[], CommandRouter | None] = lambda: None,
        token: SecretStr | None = None,
        config: UplinkConfig | None = None,
        robots: Callable[[], list[str]] = list,
    ) -> None:
        """``config``: the uplink's, for what goes through Kafka (audit topic, dead letters,
        commands); without it the console keeps its audit in memory and has neither."""
        self.settings = settings
        self.session = session
        self._router = router
        self._token = token
        self.config = config
        self._robots = robots
        self.http: HttpServer | None = None
        self.history = History()
        self.sampler: HistorySampler | None = None
        self.audit: Audit = MemoryAudit()
        self._tails: list[KafkaTail] = []
        self._registry: SchemaRegistry | None = None
        self._commands: KafkaCommands | None = None

    def start(self) -> UplinkConsole:
        """Load the token and users, check the exposure, start the history sampler, the Kafka
        operations and the HTTP server; returns the console (unchanged when it runs already)."""
        if self.http is not None:
            return self
        s = self.settings
        token = self._token if self._token is not None else load_console_token(s.token_env, s.token_file)
        users = load_users(s.users_file)
        check_console_exposure(s, token, users=bool(users))
        sites = ZenohSites(
            self.session,
            token=token,
            timeout_s=s.query_timeout,
            commands=lambda: command_view(self._router()),
        )
        ops = Operations(history=self.history)
        if self.config is not None:
            ops = self._kafka_operations(self.config, ops)
        self.audit = ops.audit
        self.sampler = HistorySampler(sites, self.history, interval_s=s.history_step).start()
        app = FastAPI(title="fleetlink fleet console", docs_url=None, redoc_url=None, openapi_url=None)
        app.mount(
            "/console",
            create_console_app(
                sites,
                token=token,
                users=users,
                ops=ops,
                poll_interval_s=s.poll_interval,
                session_ttl_s=s.session_ttl,
            ),
        )

        @app.get("/", include_in_schema=False)
        def front() -> RedirectResponse:
            return RedirectResponse("/console/", status_code=303)

        self.http = HttpServer(app, s.listen, name="uplink-console").start()
        log.info("fleet console on %s/console/", self.http.url)
        return self

    def _kafka_operations(self, config: UplinkConfig, ops: Operations) -> Operations:
        kafka = config.kafka
        ops.audit = KafkaAudit(kafka.producer_config(), config.topics.audit)
        consumer = kafka.consumer_config("fleetlink-console")
        dead = KafkaTail(consumer, config.topics.dead_letter).start()
        book = StatusBook(decode_status)
        statuses = KafkaTail(consumer, config.topics.command_status, on_record=book.on_record).start()
        self._tails = [dead, statuses]
        ops.dead_letters = KafkaDeadLetters(dead)
        if config.commands or config.services or config.actions:
            registry = self._registry = SchemaRegistry(config.registry.url)
            registry.start()
            books = [book]
            outcomes = [(service.reply_to, "correlation_id") for service in config.services] + [
                (action.result_to, "goal_id") for action in config.actions
            ]
            for topic, id_field in outcomes:
                calls = StatusBook(lambda value: decode_registered(registry, value), id_field=id_field)
                books.append(calls)
                self._tails.append(KafkaTail(consumer, topic, on_record=calls.on_record).start())
            ops.commands = self._commands = KafkaCommands(
                kafka.producer_config(),
                [
                    {
                        "name": m.name,
                        "kind": "command",
                        "from": m.from_,
                        "to": m.to,
                        "type": m.type,
                        "robot": m.robot,
                        "broadcast": m.broadcast,
                    }
                    for m in config.commands
                ]
                + [
                    {"name": m.name, "kind": "service", "from": m.from_, "to": m.to, "type": m.type}
                    for m in config.services
                ]
                + [
                    {"name": m.name, "kind": "action", "from": m.from_, "to": m.to, "type": m.type}
                    for m in config.actions
                ],
                schema_for=lambda topic, ros_type: command_schema(registry, topic, ros_type),
                register=registry.register,
                statuses=books,
                robots=self._robots,
            )
        return ops

    def stop(self) -> None:
        """Stop the history sampler, the HTTP server, the Kafka tails and producers, the registry client."""
        if self.sampler is not None:
            self.sampler.stop()
            self.sampler = None
        if self.http is not None:
            self.http.stop()
            self.http = None
        for tail in self._tails:
            tail.stop()
        self._tails = []
        if isinstance(self.audit, KafkaAudit):
            self.audit.close()
        if self._commands is not None:
            self._commands.close()
            self._commands = None
        if self._registry is not None:
            self._registry.stop()
            self._registry = None

    @property
    def url(self) -> str:
        """The console server's base URL (pages under ``/console/``); raises ``ConsoleError`` when it
        is not running."""
        if self.http is None:
            raise ConsoleError("the fleet console is not running")
        return self.http.url

    def __enter__(self) -> UplinkConsole:
        return self.start()

    def __exit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        self.stop()


def decode_status(value: bytes) -> dict[str, Any]:
    """A command status record's value (Confluent header + Avro body of ``STATUS_SCHEMA``)."""
    datum = fastavro.schemaless_reader(io.BytesIO(value[5:]), _STATUS)
    return datum if isinstance(datum, dict) else {}


_STATUS = fastavro.parse_schema(json.loads(json.dumps(STATUS_SCHEMA)))


def decode_registered(registry: SchemaRegistry, value: bytes) -> dict[str, Any]:
    """A record the uplink wrote (a call's reply, a goal's result): Confluent header, then the Avro
    body of the schema its id names in the registry (``{}`` for anything else)."""
    if len(value) < 5 or value[0] != 0:
        return {}
    try:
        schema = registry.schema_by_id(int.from_bytes(value[1:5], "big"))
        datum = fastavro.schemaless_reader(io.BytesIO(value[5:]), fastavro.parse_schema(schema))
    except (RegistryError, ValueError, EOFError) as exc:
        log.debug("console: an outcome record does not decode: %s", exc)
        return {}
    return datum if isinstance(datum, dict) else {}


def command_schema(registry: SchemaRegistry, topic: str, ros_type: str) -> dict[str, Any]:
    """The value schema commands of ``topic`` are written with: the newest registered for the
    topic (what the fleet's apps use), else the one fleetlink derives from ``ros_type``."""
    try:
        return registry.latest(f"{topic}-value")[2]
    except RegistryError:
        return avro_schema(_typestore(), ros_type, "jazzy")


@functools.cache
def _typestore() -> Typestore:
    return load_typestore("jazzy", bundled_message_paths())


def uplink_console(
    settings: ConsoleSection, *, token: SecretStr | None = None
) -> Callable[[Uplink], UplinkConsole]:
    """The fleet console as an uplink extension (``Uplink(..., extensions=[...])``)."""

    def make(uplink: Uplink) -> UplinkConsole:
        return UplinkConsole(
            settings,
            session=uplink.session,
            router=lambda: uplink.commands,
            token=token,
            config=uplink.config,
            robots=uplink.directory.registered,
        )

    return make


def check_console_exposure(settings: ConsoleSection, token: SecretStr | None, *, users: bool = False) -> None:
    """Closed by default: no token, no users and a non-loopback ``console.listen`` is a start-up error."""
    check_exposure(
        settings.listen,
        has_token=token is not None or users,
        key="console.listen",
        what="the fleet console",
        credentials_from=f"console.token_file or ${settings.token_env or 'FLEETLINK_ADMIN_TOKEN'}",
        log=log,
    )


def console_extensions(config: UplinkConfig) -> list[Callable[[Uplink], UplinkConsole]]:
    """The extensions an uplink process runs for ``config``: the fleet console when it has one
    (its exposure is checked here, before the uplink opens anything)."""
    if config.console is None:
        return []
    settings = config.console
    users = load_users(settings.users_file)  # a users file that does not validate fails the start
    check_console_exposure(
        settings, load_console_token(settings.token_env, settings.token_file), users=bool(users)
    )
    return [uplink_console(settings)]
