"""The console's web app: pages (server-rendered, Jinja2), the JSON they poll, and the changes
they send, on a ``Sites`` source (one edge's site, or the whole fleet over Zenoh).

Routes (relative to where the app is mounted, ``/console/``; role needed in brackets)::

    GET  /                       the fleet: sites, delivery, commands (an edge goes to its site) [viewer]
    GET  /sites/<site>           one site: health, graph, robots, mappings, history, robot types [viewer]
    GET  /sites/<site>/robots/<robot>   a robot: latest values, registration history, commands [viewer]
    GET  /sites/<site>/dead-letters     the dead-letter browser (every site: /dead-letters)      [viewer]
    GET  /audit                  the audit records this process wrote                            [admin]
    GET  /login, POST /login     sign in (user and password, or the admin token); POST /logout
    GET  /api/me, /api/sites, /api/sites/<site>, /api/delivery, /api/commands                    [viewer]
    GET  /api/sites/<site>/robots/<robot>, /api/sites/<site>/history, /api/history               [viewer]
    GET  /api/dead-letters, /api/dead-letters/<partition>/<offset>/raw                          [viewer]
    POST /api/sites/<site>/mappings, PUT|DELETE .../mappings/<name>, POST .../dry-run          [operator]
    GET  /api/command-mappings, /api/commands/status?ids=...                                    [viewer]
    POST /api/commands/send      one command through the command topic                         [operator]
    PUT|DELETE /api/sites/<site>/robot-types/<name>                                               [admin]
    GET  /api/audit                                                                               [admin]
    GET  /static/...             the page's script and style sheet (shipped in the package)

Every change and every command is audited (``fleetlink.console.audit``): who, what, when, and
the answer. Refusals keep the admin API's status and list each problem under the form field it
concerns (``fields``: field -> messages). Pages send no inline script or style (a strict CSP).
"""

from __future__ import annotations

import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Annotated, Any
from urllib.parse import parse_qs, quote

from fastapi import Depends, FastAPI, Path, Request
from fastapi.exceptions import RequestValidationError
from fastapi.responses import HTMLResponse, JSONResponse, RedirectResponse, Response
from fastapi.staticfiles import StaticFiles
from pydantic import SecretStr
from starlette.exceptions import HTTPException as StarletteHTTPException

from fleetlink import __version__
from fleetlink.common.extras import missing_extra
from fleetlink.common.login_limiter import LoginLimiter
from fleetlink.common.names import site_problem
from fleetlink.console.audit import Audit, MemoryAudit, audit_entry
from fleetlink.console.auth import CHANGE_HEADER, COOKIE, OPEN, SESSION_TTL_S, Authenticator, Identity
from fleetlink.console.delivery import delivery_view
from fleetlink.console.envelope import Envelope
from fleetlink.console.errors import FormError
from fleetlink.console.forms import (
    CommandForm,
    MappingForm,
    RobotTypeForm,
    field_errors,
    mapping_body,
    parse_value,
    refusal_fields,
    robot_type_body,
)
from fleetlink.console.history import History
from fleetlink.console.operations import CommandRefusedError, Commands, DeadLetters
from fleetlink.console.rates import RateBoard
from fleetlink.console.sources import Sites
from fleetlink.console.users import Role, User
from fleetlink.console.views import robot_view, site_view

try:
    from jinja2 import Environment, PackageLoader, select_autoescape
except ModuleNotFoundError as exc:  # pip install fleetlink leaves the console out
    raise missing_extra(exc, "console") from None

SiteParam = Annotated[str, Path(pattern=r"^[A-Za-z0-9_.-]+$", max_length=128)]
NameParam = Annotated[str, Path(pattern=r"^[A-Za-z0-9_.-]+$", max_length=128)]
_HEADERS = {
    "Content-Security-Policy": "default-src 'self'; img-src 'self' data:; object-src 'none'; "
    "base-uri 'none'; form-action 'self'; frame-ancestors 'none'",
    "X-Content-Type-Options": "nosniff",
    "Referrer-Policy": "same-origin",
    "Cache-Control": "no-store",
}
_SIGN_IN = "sign in (or send Authorization: Bearer <admin token>, or Basic <user:password>)"


def base_path(request: Request) -> str:
    """Where the console is mounted, ending in ``/`` (``/console/``)."""
    return str(request.scope.get("root_path", "")).rstrip("/") + "/"


def _json(data: Any, status: int = 200) -> JSONResponse:
    return JSONResponse(data, status_code=status, headers=_HEADERS)


def _refused(
    status: int,
    message: str,
    fields: dict[str, list[str]] | None = None,
    problems: list[dict[str, Any]] | None = None,
) -> JSONResponse:
    return _json(
        {"ok": False, "status": status, "error": message, "fields": fields or {}, "problems": problems or []},
        status,
    )


def _change(env: Envelope) -> JSONResponse:
    if env.ok:
        return _json({"ok": True, "status": env.status, "result": env.body}, env.status)
    status = env.status if 400 <= env.status < 600 else 502
    fields = refusal_fields(env.status, env.error, env.problems)
    return _refused(status, env.error or f"refused ({env.status})", fields, list(env.problems))


def _form_change(
    form: MappingForm, send: Callable[[dict[str, Any]], Envelope], *, with_name: bool = True
) -> JSONResponse:
    try:
        body = mapping_body(form, with_name=with_name)
    except FormError as exc:
        return _refused(422, str(exc), exc.fields)
    return _change(send(body))


class _Denied(Exception):  # noqa: N818 - an internal signal turned into a 401/403/429 answer
    def __init__(self, status: int, message: str, *, retry_after: float | None = None) -> None:
        super().__init__(message)
        self.status = status
        self.retry_after = retry_after


def _client(request: Request) -> str:
    return request.client.host if request.client is not None else "?"


class _Console:
    """What the routes share: the source, who may do what, the audit, the templates, the rates."""

    def __init__(self, sites: Sites, auth: Authenticator, ops: Operations, poll_interval_s: float) -> None:
        self.sites = sites
        self.auth = auth
        self.ops = ops
        self.poll_interval_s = poll_interval_s
        self.clock = ops.clock
        self.logins = LoginLimiter(clock=ops.clock)
        self.templates = Environment(
            loader=PackageLoader("fleetlink.console", "templates"), autoescape=select_autoescape(["html"])
        )
        self.board = RateBoard(
            window_s=max(5.0, 4 * poll_interval_s), min_span_s=min(0.5, poll_interval_s / 2)
        )

    def identity(self, request: Request) -> Identity | None:
        if self.auth.open:
            return OPEN
        client = _client(request)
        wait = self.logins.retry_after(client)
        if wait > 0:
            raise _Denied(429, f"too many wrong sign-ins: try again in {wait:.0f} s", retry_after=wait)
        who, tried = self.auth.identify(
            authorization=request.headers.get("authorization"),
            cookie=request.cookies.get(COOKIE),
            now=self.clock(),
        )
        if tried:  # a credential was tried in a header: count it (an old cookie is not)
            (self.logins.success if who is not None else self.logins.failure)(client)
        return who

    def needs(self, role: Role) -> Callable[[Request], Identity]:
        def check(request: Request) -> Identity:
            who = self.identity(request)
            if who is None:
                raise _Denied(401, _SIGN_IN)
            if not who.may(role):
                raise _Denied(403, f"{who.user} is a {who.role}: this needs the {role} role")
            changing = request.method not in ("GET", "HEAD")  # a read needs no header, whatever the role
            if changing and who.by_cookie and request.headers.get(CHANGE_HEADER) != "1":
                raise _Denied(403, "changes from a console page must carry the X-Fleetlink-Console header")
            return who

        return check

    def audit(
        self,
        who: Identity,
        action: str,
        response: JSONResponse,
        *,
        site: str | None = None,
        target: str | None = None,
        detail: dict[str, Any] | None = None,
    ) -> JSONResponse:
        """Record ``action`` with its answer; a record that could not be written is said in the answer."""
        entry = audit_entry(
            who,
            action,
            process=self.sites.process,
            at=self.clock(),
            site=site,
            target=target,
            status=response.status_code,
            detail=detail,
        )
        problem = self.ops.audit.record(entry)
        if problem is not None:
            response.headers["X-Fleetlink-Audit"] = problem[:200]
        return response

    def page(self, request: Request, name: str, status: int = 200, **values: Any) -> HTMLResponse:
        who = values.pop("who", None)
        html = self.templates.get_template(name).render(
            base=base_path(request),
            process=self.sites.process,
            version=__version__,
            signed_in=not self.auth.open,
            poll_ms=int(self.poll_interval_s * 1000),
            user=who.user if isinstance(who, Identity) else None,
            role=who.role if isinstance(who, Identity) else None,
            has_users=bool(self.auth.users),
            **values,
        )
        return HTMLResponse(html, status_code=status, headers=_HEADERS)

    def to_login(self, request: Request) -> RedirectResponse:
        wanted = quote(request.url.path, safe="/")
        return RedirectResponse(f"{base_path(request)}login?next={wanted}", status_code=303, headers=_HEADERS)


@dataclass
class Operations:
    """What a process offers besides its sites: the audit, dead letters, commands, history."""

    audit: Audit = field(default_factory=MemoryAudit)
    dead_letters: DeadLetters | None = None
    commands: Commands | None = None
    history: History | None = None
    clock: Callable[[], float] = time.time


def _needs(role: Role) -> Callable[[Request], Identity]:
    """A route's dependency: who asks, refused (401/403) below ``role``. The console is the
    mounted app's state (module-level, so FastAPI resolves the annotations)."""

    def check(request: Request) -> Identity:
        console: _Console = request.app.state.console
        return console.needs(role)(request)

    return check


Viewer = Annotated[Identity, Depends(_needs("viewer"))]
Operator = Annotated[Identity, Depends(_needs("operator"))]
Admin = Annotated[Identity, Depends(_needs("admin"))]


def create_console_app(
    sites: Sites,
    *,
    token: SecretStr | None,
    users: Mapping[str, User] | None = None,
    ops: Operations | None = None,
    poll_interval_s: float = 1.0,
    clock: Callable[[], float] | None = None,
    session_ttl_s: float = SESSION_TTL_S,
) -> FastAPI:
    """The console's FastAPI app on ``sites``: pages, JSON API and static files, to mount under ``/console/``.

    Who may sign in comes from ``token`` and ``users`` (neither: the console is open); ``ops`` adds
    the audit, dead letters, commands and history; ``clock`` replaces ``ops.clock``.
    """
    app = FastAPI(
        title="fleetlink console", version=__version__, docs_url=None, redoc_url=None, openapi_url=None
    )
    app.mount("/static", StaticFiles(packages=[("fleetlink.console", "static")]), name="static")
    ops = ops or Operations()
    if clock is not None:
        ops.clock = clock
    console = _Console(sites, Authenticator(token, users, ttl_s=session_ttl_s), ops, poll_interval_s)
    app.state.console = console

    @app.exception_handler(_Denied)
    def on_denied(_request: Request, exc: _Denied) -> JSONResponse:
        response = _refused(exc.status, str(exc))
        if exc.retry_after is not None:
            response.headers["Retry-After"] = str(max(1, round(exc.retry_after)))
        return response

    @app.exception_handler(RequestValidationError)
    def on_invalid(_request: Request, exc: RequestValidationError) -> JSONResponse:
        problems = [
            {"path": ".".join(str(p) for p in e.get("loc", ())[1:]) or "<root>", "message": str(e["msg"])}
            for e in exc.errors()
        ]
        return _refused(422, "invalid request", field_errors(problems), problems)

    @app.exception_handler(StarletteHTTPException)
    def on_http_error(_request: Request, exc: StarletteHTTPException) -> JSONResponse:
        return _refused(exc.status_code, str(exc.detail))

    _page_routes(app, console)
    _api_routes(app, console)
    _operator_routes(app, console)
    return app


def _page_routes(app: FastAPI, console: _Console) -> None:
    sites = console.sites

    def signed_in(request: Request) -> Identity | None:
        try:
            return console.identity(request)
        except _Denied:
            return None

    @app.get("/", response_model=None)
    def fleet_page(request: Request) -> Response:
        who = signed_in(request)
        if who is None:
            return console.to_login(request)
        if sites.process == "edge":
            found = sites.sites()
            if len(found) == 1:
                return RedirectResponse(f"{base_path(request)}sites/{found[0]['site']}", status_code=303)
        return console.page(request, "fleet.html", who=who)

    @app.get("/sites/{site}", response_model=None)
    def site_page(request: Request, site: SiteParam) -> Response:
        who = signed_in(request)
        if who is None:
            return console.to_login(request)
        return console.page(request, "site.html", site=site, who=who)

    @app.get("/sites/{site}/robots/{robot}", response_model=None)
    def robot_page(request: Request, site: SiteParam, robot: NameParam) -> Response:
        who = signed_in(request)
        if who is None:
            return console.to_login(request)
        return console.page(request, "robot.html", site=site, robot=robot, who=who)

    @app.get("/sites/{site}/dead-letters", response_model=None)
    def site_dead_letters_page(request: Request, site: SiteParam) -> Response:
        who = signed_in(request)
        if who is None:
            return console.to_login(request)
        return console.page(request, "dead_letters.html", site=site, who=who)

    @app.get("/dead-letters", response_model=None)
    def dead_letters_page(request: Request) -> Response:
        who = signed_in(request)
        if who is None:
            return console.to_login(request)
        return console.page(request, "dead_letters.html", site="", who=who)

    @app.get("/audit", response_model=None)
    def audit_page(request: Request) -> Response:
        who = signed_in(request)
        if who is None:
            return console.to_login(request)
        return console.page(request, "audit.html", who=who, where=console.ops.audit.where)

    @app.get("/login", response_model=None)
    def login_page(request: Request, next: str = "") -> Response:
        return console.page(request, "login.html", next=_safe_next(request, next), error=None)

    @app.post("/login", response_model=None)
    async def login(request: Request) -> Response:
        form = parse_qs((await request.body()).decode("utf-8", "replace"), max_num_fields=10)
        name = (form.get("user") or [""])[0][:64]
        given = (form.get("token") or [""])[0][:1024]
        target = _safe_next(request, (form.get("next") or [""])[0])
        client = _client(request)
        if console.auth.open:
            return RedirectResponse(target, status_code=303, headers=_HEADERS)
        wait = console.logins.retry_after(client)
        if wait > 0:
            error = f"too many wrong sign-ins: try again in {wait:.0f} s"
            return console.page(request, "login.html", status=429, next=target, error=error)
        who = console.auth.sign_in(name, given)
        if who is None:
            console.logins.failure(client)
            error = "wrong user or password" if name.strip() else "wrong token"
            return console.page(request, "login.html", status=401, next=target, error=error)
        console.logins.success(client)
        response = RedirectResponse(target, status_code=303, headers=_HEADERS)
        response.set_cookie(
            COOKIE,
            console.auth.cookie(who, now=console.clock()),
            max_age=int(console.auth.ttl_s),
            httponly=True,
            samesite="strict",
            path=base_path(request),
            secure=request.url.scheme == "https",
        )
        return response

    @app.post("/logout", response_model=None)
    def logout(request: Request) -> Response:
        response = RedirectResponse(f"{base_path(request)}login", status_code=303, headers=_HEADERS)
        response.delete_cookie(COOKIE, path=base_path(request))
        return response


def _api_routes(app: FastAPI, console: _Console) -> None:
    sites = console.sites

    @app.get("/api/me")
    def api_me(who: Viewer) -> JSONResponse:
        return _json({"user": who.user, "role": who.role, "process": sites.process})

    @app.get("/api/sites")
    def api_sites(_who: Viewer) -> JSONResponse:
        return _json({"process": sites.process, "at": console.clock(), "sites": sites.sites()})

    @app.get("/api/sites/{site}")
    def api_site(site: SiteParam, _who: Viewer) -> JSONResponse:
        parts = sites.read(site)
        view = site_view(site, parts, console.board, now=console.clock(), delivery=sites.delivery(site))
        view["process"] = sites.process
        return _json(view)

    @app.get("/api/delivery")
    def api_delivery(_who: Viewer) -> JSONResponse:
        answers = sites.delivery(None)
        if answers is None:
            return _json({"process": sites.process, "available": False})
        view = delivery_view(console.board, answers, now=console.clock())
        return _json({"process": sites.process, "available": True, "at": console.clock(), **view})

    @app.get("/api/commands")
    def api_commands(_who: Viewer) -> JSONResponse:
        return _json({"process": sites.process, **sites.commands()})

    @app.get("/api/sites/{site}/robots/{robot}")
    def api_robot(site: SiteParam, robot: NameParam, _who: Viewer) -> JSONResponse:
        return _json(robot_view(site, robot, sites.read(site), sites.latest(site, robot)))

    @app.get("/api/sites/{site}/history")
    def api_site_history(site: SiteParam, _who: Viewer) -> JSONResponse:
        history = console.ops.history
        if history is None:
            return _json({"available": False, "reason": "this process keeps no history"})
        now = console.clock()
        return _json(
            {
                "available": True,
                "window_s": history.window_s,
                "step_s": history.step_s,
                "site": history.points(("site", site), now),
                "mappings": history.points(("mapping", site), now),
            }
        )

    @app.get("/api/audit")
    def api_audit(_who: Admin, limit: int = 100) -> JSONResponse:
        audit = console.ops.audit
        return _json({"where": audit.where, "records": audit.recent(max(1, min(limit, 500)))})

    @app.post("/api/sites/{site}/mappings")
    def add_mapping(site: SiteParam, form: MappingForm, who: Operator) -> JSONResponse:
        response = _form_change(form, lambda body: sites.ask(site, "mappings", op="add", body=body))
        return console.audit(
            who, "mapping.add", response, site=site, target=form.name, detail=form_detail(form)
        )

    @app.put("/api/sites/{site}/mappings/{name}")
    def change_mapping(site: SiteParam, name: NameParam, form: MappingForm, who: Operator) -> JSONResponse:
        response = _form_change(
            form, lambda body: sites.ask(site, f"mappings/{name}", op="put", body=body), with_name=False
        )
        return console.audit(
            who, "mapping.change", response, site=site, target=name, detail=form_detail(form)
        )

    @app.delete("/api/sites/{site}/mappings/{name}")
    def remove_mapping(site: SiteParam, name: NameParam, who: Operator) -> JSONResponse:
        response = _change(sites.ask(site, f"mappings/{name}", op="delete"))
        return console.audit(who, "mapping.remove", response, site=site, target=name)

    @app.post("/api/sites/{site}/dry-run")
    def dry_run(site: SiteParam, form: MappingForm, _who: Operator) -> JSONResponse:
        return _form_change(form, lambda body: sites.ask(site, "dry-run", op="dry-run", body=body))

    @app.put("/api/sites/{site}/robot-types/{name}")
    def put_robot_type(site: SiteParam, name: NameParam, form: RobotTypeForm, who: Admin) -> JSONResponse:
        try:
            body = robot_type_body(form)
        except FormError as exc:
            response = _refused(422, str(exc), exc.fields)
        else:
            response = _change(sites.ask(site, f"robot_types/{name}", op="put", body=body))
        return console.audit(
            who, "robot_type.put", response, site=site, target=name, detail=form.model_dump(by_alias=True)
        )

    @app.delete("/api/sites/{site}/robot-types/{name}")
    def remove_robot_type(site: SiteParam, name: NameParam, who: Admin) -> JSONResponse:
        response = _change(sites.ask(site, f"robot_types/{name}", op="delete"))
        return console.audit(who, "robot_type.remove", response, site=site, target=name)


def _operator_routes(app: FastAPI, console: _Console) -> None:
    ops = console.ops

    @app.get("/api/dead-letters")
    def api_dead_letters(_who: Viewer, site: str = "", limit: int = 50) -> JSONResponse:
        if ops.dead_letters is None:
            return _json({"available": False, "reason": NO_KAFKA})
        if site and site_problem(site) is not None:
            return _refused(400, f"not a site name: {site!r}")
        records = ops.dead_letters.recent(site or None, max(1, min(limit, 500)))
        return _json({"available": True, "site": site or None, "records": records})

    @app.get("/api/dead-letters/{partition}/{offset}/raw", response_model=None)
    def api_dead_letter_raw(partition: int, offset: int, _who: Viewer) -> Response:
        if ops.dead_letters is None:
            return _refused(404, NO_KAFKA)
        data = ops.dead_letters.raw(partition, offset)
        if data is None:
            return _refused(404, f"no dead letter at partition {partition}, offset {offset}")
        name = f"dead-letter-{partition}-{offset}.bin"
        headers = {**_HEADERS, "Content-Disposition": f'attachment; filename="{name}"'}
        return Response(data, media_type="application/octet-stream", headers=headers)

    @app.get("/api/command-mappings")
    def api_command_mappings(_who: Viewer) -> JSONResponse:
        if ops.commands is None:
            return _json({"available": False, "reason": NO_COMMANDS_HERE})
        return _json({"available": True, "mappings": ops.commands.mappings()})

    @app.get("/api/commands/status")
    def api_command_status(_who: Viewer, ids: str = "") -> JSONResponse:
        if ops.commands is None:
            return _json({"available": False, "reason": NO_COMMANDS_HERE})
        wanted = [i for i in ids.split(",") if i][:50]
        return _json({"available": True, "statuses": ops.commands.statuses(wanted)})

    @app.post("/api/commands/send")
    def api_send_command(form: CommandForm, who: Operator) -> JSONResponse:
        detail = form.model_dump()
        if ops.commands is None:
            return _refused(404, NO_COMMANDS_HERE)
        try:
            value = parse_value(form.value)
            sent = ops.commands.send(form.mapping, form.robot, value, user=who.user)
        except FormError as exc:
            response = _refused(422, str(exc), exc.fields)
        except CommandRefusedError as exc:
            response = _refused(422, str(exc), {"_form": [str(exc)]})
        else:
            response = _json({"ok": True, "status": 201, "result": sent}, 201)
            detail["command_id"] = sent.get("command_id")
        return console.audit(who, "command.send", response, target=form.robot, detail=detail)


NO_KAFKA = "not available on this process: the fleet console (the uplink) reads the dead-letter topic"
NO_COMMANDS_HERE = (
    "not available on this process: commands are sent from the fleet console (the uplink) "
    "through a command mapping's Kafka topic"
)


def form_detail(form: MappingForm) -> dict[str, Any]:
    """The fields of a mapping form that have a value, for the audit record's ``detail``."""
    return {k: v for k, v in form.model_dump(by_alias=True).items() if v}


def _safe_next(request: Request, wanted: str) -> str:
    """Where to go after signing in: a path inside the console, else its front page."""
    base = base_path(request)
    if wanted.startswith(base) and "//" not in wanted and "\\" not in wanted and ".." not in wanted:
        return wanted
    return base
