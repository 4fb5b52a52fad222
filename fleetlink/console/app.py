"""The console's web app: pages (server-rendered, Jinja2), the JSON they poll, and the changes
they send, on a ``Sites`` source (one edge's site, or the whole fleet over Zenoh).

Routes (relative to where the app is mounted, ``/console/``)::

    GET  /                       the fleet: every site with its state (an edge goes to its site)
    GET  /sites/<site>           one site: health, live graph, robots, mappings + editor, commands
    GET  /login, POST /login     sign in with the token (sets the session cookie); POST /logout
    GET  /api/sites              site summaries (JSON)
    GET  /api/sites/<site>       the site view the page polls (JSON; rates from counter deltas)
    POST /api/sites/<site>/mappings          add      (the mapping form's fields as JSON)
    PUT  /api/sites/<site>/mappings/<name>   change
    DELETE /api/sites/<site>/mappings/<name> remove
    POST /api/sites/<site>/dry-run           which topics would the form's mapping match now
    GET  /api/commands           command routing status (the uplink's; an edge says it has none)
    GET  /static/...             the page's script and style sheet (shipped in the package)

Refusals keep the admin API's status and list each problem under the form field it concerns
(``fields``: field -> messages). Pages send no inline script or style (a strict CSP).
"""

from __future__ import annotations

import time
from collections.abc import Callable
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
from fleetlink.console.auth import (
    COOKIE,
    SESSION_TTL_S,
    Access,
    bearer,
    check,
    cookie_value,
    may_change,
    token_matches,
)
from fleetlink.console.delivery import delivery_view
from fleetlink.console.envelope import Envelope
from fleetlink.console.errors import FormError
from fleetlink.console.forms import MappingForm, field_errors, mapping_body, refusal_fields
from fleetlink.console.rates import RateBoard
from fleetlink.console.sources import Sites
from fleetlink.console.views import site_view

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
_SIGN_IN = "sign in with the admin token (or send Authorization: Bearer <token>)"


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
    """What the routes share: the source, the token, the templates, the rates, the clock."""

    def __init__(
        self,
        sites: Sites,
        token: SecretStr | None,
        poll_interval_s: float,
        clock: Callable[[], float],
        session_ttl_s: float,
    ) -> None:
        self.sites = sites
        self.token = token
        self.poll_interval_s = poll_interval_s
        self.clock = clock
        self.session_ttl_s = session_ttl_s
        self.logins = LoginLimiter(clock=clock)
        self.templates = Environment(
            loader=PackageLoader("fleetlink.console", "templates"), autoescape=select_autoescape(["html"])
        )
        self.board = RateBoard(
            window_s=max(5.0, 4 * poll_interval_s), min_span_s=min(0.5, poll_interval_s / 2)
        )

    def access(self, request: Request) -> Access:
        if self.token is None:
            return Access(allowed=True)
        client = _client(request)
        wait = self.logins.retry_after(client)
        if wait > 0:
            raise _Denied(429, f"too many wrong tokens: try again in {wait:.0f} s", retry_after=wait)
        authorization = request.headers.get("authorization")
        access = check(
            self.token, authorization=authorization, cookie=request.cookies.get(COOKIE), now=self.clock()
        )
        if bearer(authorization) is not None:  # a token was tried: count it (an old cookie is not)
            (self.logins.success if access.allowed and not access.by_cookie else self.logins.failure)(client)
        return access

    def reader(self, request: Request) -> None:
        if not self.access(request).allowed:
            raise _Denied(401, _SIGN_IN)

    def changer(self, request: Request) -> None:
        access = self.access(request)
        if not access.allowed:
            raise _Denied(401, _SIGN_IN)
        if not may_change(self.token, access, request.headers):
            raise _Denied(403, "changes from a console page must carry the X-Fleetlink-Console header")

    def page(self, request: Request, name: str, status: int = 200, **values: Any) -> HTMLResponse:
        html = self.templates.get_template(name).render(
            base=base_path(request),
            process=self.sites.process,
            version=__version__,
            signed_in=self.token is not None,
            poll_ms=int(self.poll_interval_s * 1000),
            **values,
        )
        return HTMLResponse(html, status_code=status, headers=_HEADERS)

    def to_login(self, request: Request) -> RedirectResponse:
        wanted = quote(request.url.path, safe="/")
        return RedirectResponse(f"{base_path(request)}login?next={wanted}", status_code=303, headers=_HEADERS)


def create_console_app(
    sites: Sites,
    *,
    token: SecretStr | None,
    poll_interval_s: float = 1.0,
    clock: Callable[[], float] = time.time,
    session_ttl_s: float = SESSION_TTL_S,
) -> FastAPI:
    app = FastAPI(
        title="fleetlink console", version=__version__, docs_url=None, redoc_url=None, openapi_url=None
    )
    app.mount("/static", StaticFiles(packages=[("fleetlink.console", "static")]), name="static")
    console = _Console(sites, token, poll_interval_s, clock, session_ttl_s)

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
    return app


def _page_routes(app: FastAPI, console: _Console) -> None:
    sites, token = console.sites, console.token

    @app.get("/", response_model=None)
    def fleet_page(request: Request) -> Response:
        if not console.access(request).allowed:
            return console.to_login(request)
        if sites.process == "edge":
            found = sites.sites()
            if len(found) == 1:
                return RedirectResponse(f"{base_path(request)}sites/{found[0]['site']}", status_code=303)
        return console.page(request, "fleet.html")

    @app.get("/sites/{site}", response_model=None)
    def site_page(request: Request, site: SiteParam) -> Response:
        if not console.access(request).allowed:
            return console.to_login(request)
        return console.page(request, "site.html", site=site)

    @app.get("/login", response_model=None)
    def login_page(request: Request, next: str = "") -> Response:
        return console.page(request, "login.html", next=_safe_next(request, next), error=None)

    @app.post("/login", response_model=None)
    async def login(request: Request) -> Response:
        form = parse_qs((await request.body()).decode("utf-8", "replace"), max_num_fields=10)
        given = (form.get("token") or [""])[0]
        target = _safe_next(request, (form.get("next") or [""])[0])
        client = _client(request)
        wait = console.logins.retry_after(client) if token is not None else 0.0
        if wait > 0:
            error = f"too many wrong tokens: try again in {wait:.0f} s"
            return console.page(request, "login.html", status=429, next=target, error=error)
        if token is not None and not token_matches(token, given):
            console.logins.failure(client)
            return console.page(request, "login.html", status=401, next=target, error="wrong token")
        console.logins.success(client)
        response = RedirectResponse(target, status_code=303, headers=_HEADERS)
        if token is not None:
            response.set_cookie(
                COOKIE,
                cookie_value(token, now=console.clock(), ttl_s=console.session_ttl_s),
                max_age=int(console.session_ttl_s),
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
    read = [Depends(console.reader)]
    change = [Depends(console.changer)]

    @app.get("/api/sites", dependencies=read)
    def api_sites() -> JSONResponse:
        return _json({"process": sites.process, "at": console.clock(), "sites": sites.sites()})

    @app.get("/api/sites/{site}", dependencies=read)
    def api_site(site: SiteParam) -> JSONResponse:
        parts = sites.read(site)
        view = site_view(site, parts, console.board, now=console.clock(), delivery=sites.delivery(site))
        view["process"] = sites.process
        return _json(view)

    @app.get("/api/delivery", dependencies=read)
    def api_delivery() -> JSONResponse:
        answers = sites.delivery(None)
        if answers is None:
            return _json({"process": sites.process, "available": False})
        view = delivery_view(console.board, answers, now=console.clock())
        return _json({"process": sites.process, "available": True, "at": console.clock(), **view})

    @app.get("/api/commands", dependencies=read)
    def api_commands() -> JSONResponse:
        return _json({"process": sites.process, **sites.commands()})

    @app.post("/api/sites/{site}/mappings", dependencies=change)
    def add_mapping(site: SiteParam, form: MappingForm) -> JSONResponse:
        return _form_change(form, lambda body: sites.ask(site, "mappings", op="add", body=body))

    @app.put("/api/sites/{site}/mappings/{name}", dependencies=change)
    def change_mapping(site: SiteParam, name: NameParam, form: MappingForm) -> JSONResponse:
        return _form_change(
            form, lambda body: sites.ask(site, f"mappings/{name}", op="put", body=body), with_name=False
        )

    @app.delete("/api/sites/{site}/mappings/{name}", dependencies=change)
    def remove_mapping(site: SiteParam, name: NameParam) -> JSONResponse:
        return _change(sites.ask(site, f"mappings/{name}", op="delete"))

    @app.post("/api/sites/{site}/dry-run", dependencies=change)
    def dry_run(site: SiteParam, form: MappingForm) -> JSONResponse:
        return _form_change(form, lambda body: sites.ask(site, "dry-run", op="dry-run", body=body))


def _safe_next(request: Request, wanted: str) -> str:
    """Where to go after signing in: a path inside the console, else its front page."""
    base = base_path(request)
    if wanted.startswith(base) and "//" not in wanted and "\\" not in wanted and ".." not in wanted:
        return wanted
    return base
