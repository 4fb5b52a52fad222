"""``UplinkConsole``: the fleet-wide console the uplink serves (every site, over Zenoh).

    console = UplinkConsole(settings, session=session, router=lambda: uplink.commands).start()
    console.url            # http://127.0.0.1:8490 ; pages under /console/
    console.stop()

Sites are found and changed through their Zenoh admin space (``ZenohSites``); what Kafka
acknowledged comes from every uplink's delivery figures (``fleetlink/<site>/delivery/<uplink>``,
this one's included); command status from its command router (``command_view``).
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from types import TracebackType
from typing import TYPE_CHECKING, Any

import zenoh
from fastapi import FastAPI
from fastapi.responses import RedirectResponse
from pydantic import SecretStr

from fleetlink.common.console_config import ConsoleSection
from fleetlink.common.exposure import check_exposure
from fleetlink.common.metrics import HttpServer
from fleetlink.console.app import create_console_app
from fleetlink.console.auth import load_console_token
from fleetlink.console.errors import ConsoleError
from fleetlink.console.remote import ZenohSites

if TYPE_CHECKING:
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
    def __init__(
        self,
        settings: ConsoleSection,
        *,
        session: zenoh.Session,
        router: Callable[[], CommandRouter | None] = lambda: None,
        token: SecretStr | None = None,
    ) -> None:
        self.settings = settings
        self.session = session
        self._router = router
        self._token = token
        self.http: HttpServer | None = None

    def start(self) -> UplinkConsole:
        if self.http is not None:
            return self
        s = self.settings
        token = self._token if self._token is not None else load_console_token(s.token_env, s.token_file)
        check_console_exposure(s, token)
        sites = ZenohSites(
            self.session,
            token=token,
            timeout_s=s.query_timeout,
            commands=lambda: command_view(self._router()),
        )
        app = FastAPI(title="fleetlink fleet console", docs_url=None, redoc_url=None, openapi_url=None)
        app.mount(
            "/console",
            create_console_app(
                sites, token=token, poll_interval_s=s.poll_interval, session_ttl_s=s.session_ttl
            ),
        )

        @app.get("/", include_in_schema=False)
        def front() -> RedirectResponse:
            return RedirectResponse("/console/", status_code=303)

        self.http = HttpServer(app, s.listen, name="uplink-console").start()
        log.info("fleet console on %s/console/", self.http.url)
        return self

    def stop(self) -> None:
        if self.http is not None:
            self.http.stop()
            self.http = None

    @property
    def url(self) -> str:
        if self.http is None:
            raise ConsoleError("the fleet console is not running")
        return self.http.url

    def __enter__(self) -> UplinkConsole:
        return self.start()

    def __exit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        self.stop()


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
        )

    return make


def check_console_exposure(settings: ConsoleSection, token: SecretStr | None) -> None:
    """Closed by default: no token and a non-loopback ``console.listen`` is a start-up error."""
    check_exposure(
        settings.listen,
        has_token=token is not None,
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
    check_console_exposure(settings, load_console_token(settings.token_env, settings.token_file))
    return [uplink_console(settings)]
