"""The admin API over HTTP: a FastAPI app on the ``AdminService`` (OpenAPI at ``/openapi.json``).

Every admin route needs ``Authorization: Bearer <token>`` when a token is configured (401
otherwise); after a few wrong tokens a client is locked out for a while (429 with
``Retry-After``, ``fleetlink.common.login_limiter``). ``/health``, ``/metrics`` and
``/openapi.json`` stay open for probes and scrapers.
Errors are JSON ``ErrorView`` objects; validation errors (422) list each problem with its path
in the request body, as ``fleetlink validate`` writes YAML paths.
"""

from __future__ import annotations

from typing import Annotated, Any

from fastapi import APIRouter, Depends, FastAPI, Path, Request, Response
from fastapi.exceptions import RequestValidationError
from fastapi.responses import JSONResponse
from pydantic import SecretStr
from starlette.exceptions import HTTPException as StarletteHTTPException

from fleetlink import __version__
from fleetlink.common.configfile import format_path
from fleetlink.common.login_limiter import LoginLimiter
from fleetlink.common.metrics import PrometheusMetrics, add_metrics_routes
from fleetlink.edge.admin.auth import authorized
from fleetlink.edge.admin.bodies import DryRunBody, MappingBody, MappingChangeBody, RobotTypeBody, raw
from fleetlink.edge.admin.errors import (
    AdminError,
    FieldProblem,
    InvalidChangeError,
    TooManyAttemptsError,
    UnauthorizedError,
)
from fleetlink.edge.admin.overlay import Overlay
from fleetlink.edge.admin.problems import document_path, message_of
from fleetlink.edge.admin.service import AdminService
from fleetlink.edge.admin.views import (
    ChangeView,
    DamageAckView,
    DamageView,
    DryRunView,
    ErrorView,
    MappingView,
    ProblemView,
    RobotTypeView,
    RobotView,
    TopicView,
)

NameParam = Annotated[str, Path(pattern=r"^[A-Za-z0-9_.-]+$", max_length=128)]
_ERRORS: dict[int | str, dict[str, Any]] = {
    code: {"model": ErrorView, "description": text}
    for code, text in (
        (400, "the body cannot be read (not JSON)"),
        (401, "missing or wrong admin token"),
        (429, "too many wrong tokens from this client: wait Retry-After seconds"),
        (404, "not found"),
        (409, "name taken"),
        (422, "invalid: each problem names its field"),
        (503, "could not be saved; not applied"),
    )
}


def error_response(
    status: int, message: str, problems: tuple[FieldProblem, ...] = (), *, retry_after: float | None = None
) -> JSONResponse:
    """An ``ErrorView`` JSON response; 401 adds ``WWW-Authenticate: Bearer``, ``retry_after`` (seconds) a
    ``Retry-After`` header."""
    views = [ProblemView(path=p.path, message=p.message, config_path=p.config_path) for p in problems]
    body = ErrorView(status=status, error=message, problems=views)
    headers = {"WWW-Authenticate": "Bearer"} if status == 401 else {}
    if retry_after is not None:
        headers["Retry-After"] = str(max(1, round(retry_after)))
    return JSONResponse(body.model_dump(mode="json"), status_code=status, headers=headers or None)


def create_app(
    service: AdminService,
    *,
    token: SecretStr | None = None,
    metrics: PrometheusMetrics | None = None,
    limiter: LoginLimiter | None = None,
) -> FastAPI:
    """The admin API's FastAPI app on ``service``: token check with lockout, the admin routes, ``/metrics``
    and ``/health`` when ``metrics`` is given, and JSON error handlers."""
    app = FastAPI(
        title="fleetlink edge admin",
        version=__version__,
        docs_url=None,
        redoc_url=None,
        description="Robots, topics and mappings of one fleetlink edge; change mappings and robot types "
        "at runtime (validated like the config file, saved, applied atomically).",
    )

    logins = limiter if limiter is not None else LoginLimiter()

    def require_token(request: Request) -> None:
        if token is None:
            return
        client = request.client.host if request.client is not None else "?"
        wait = logins.retry_after(client)
        if wait > 0:
            if metrics is not None:
                metrics.on_admin_refused("locked_out")
            raise TooManyAttemptsError(wait)
        header = request.headers.get("authorization")
        if authorized(token, header):
            logins.success(client)
            return
        if header is not None:  # a wrong token, not a request that forgot it
            logins.failure(client)
            if metrics is not None:
                metrics.on_admin_refused("wrong_token")
        raise UnauthorizedError("missing or wrong admin token (Authorization: Bearer <token>)")

    router = APIRouter(dependencies=[Depends(require_token)], responses=_ERRORS)
    _routes(router, service)
    app.include_router(router)
    if metrics is not None:
        add_metrics_routes(app, metrics, service.health, refresh=None)

    @app.exception_handler(AdminError)
    def on_admin_error(_request: Request, exc: AdminError) -> JSONResponse:
        problems = exc.problems if isinstance(exc, InvalidChangeError) else ()
        message = exc.summary if isinstance(exc, InvalidChangeError) else str(exc)
        wait = exc.retry_after if isinstance(exc, TooManyAttemptsError) else None
        return error_response(exc.status, message, problems, retry_after=wait)

    @app.exception_handler(StarletteHTTPException)
    def on_http_error(_request: Request, exc: StarletteHTTPException) -> JSONResponse:
        return error_response(exc.status_code, str(exc.detail))

    @app.exception_handler(RequestValidationError)
    def on_invalid(_request: Request, exc: RequestValidationError) -> JSONResponse:
        problems = []
        for error in exc.errors():
            loc = list(error.get("loc", ()))
            where = loc[0] if loc else "body"
            rest = document_path(loc[1:], exc.body) if where == "body" else (where, *loc[1:])
            problems.append(FieldProblem(path=format_path(rest), message=message_of(error)))
        return error_response(422, "invalid request", tuple(problems))

    return app


def _routes(router: APIRouter, service: AdminService) -> None:
    @router.get("/robots", tags=["graph"])
    def get_robots() -> list[RobotView]:
        """Registered robots: type, since when, state."""
        return service.robots()

    @router.get("/topics", tags=["graph"])
    def get_topics() -> list[TopicView]:
        """Discovered ROS topics, their types and publishers, and the mappings each one feeds."""
        return service.topics()

    @router.get("/mappings", tags=["mappings"])
    def get_mappings() -> list[MappingView]:
        """Every mapping with its live counters (per mapping and per stage)."""
        return service.mappings()

    @router.post("/mappings", tags=["mappings"], status_code=201)
    def post_mapping(body: MappingBody) -> ChangeView:
        """Add a mapping (site-level, or a robot type's template when ``robot_type`` is set)."""
        return service.add_mapping(raw(body))

    @router.get("/mappings/{name}", tags=["mappings"])
    def get_mapping(name: NameParam) -> MappingView:
        return service.mapping(name)

    @router.put("/mappings/{name}", tags=["mappings"])
    def put_mapping(name: NameParam, body: MappingChangeBody) -> ChangeView:
        """Change a mapping (the body replaces it; its name cannot change)."""
        return service.change_mapping(name, {"name": name, **raw(body)})

    @router.delete("/mappings/{name}", tags=["mappings"])
    def delete_mapping(name: NameParam) -> ChangeView:
        return service.remove_mapping(name)

    @router.post("/dry-run", tags=["mappings"])
    def dry_run(body: DryRunBody) -> DryRunView:
        """Which discovered topics this mapping would match now. Nothing is changed."""
        return service.dry_run(raw(body))

    @router.get("/robot_types", tags=["robot types"])
    def get_robot_types() -> list[RobotTypeView]:
        return service.robot_types()

    @router.put("/robot_types/{name}", tags=["robot types"], responses={201: {"model": ChangeView}})
    def put_robot_type(name: NameParam, body: RobotTypeBody, response: Response) -> ChangeView:
        """Create or change a robot type."""
        change = service.put_robot_type(name, raw(body))
        response.status_code = 201 if change.status == "created" else 200
        return change

    @router.delete("/robot_types/{name}", tags=["robot types"])
    def delete_robot_type(name: NameParam) -> ChangeView:
        """Remove a robot type and its mappings (its robots are deregistered)."""
        return service.remove_robot_type(name)

    @router.get("/spool/damage", tags=["spool"])
    def get_spool_damage() -> list[DamageView]:
        """Damage found in the durable spool (missing or corrupt segments, lost ledger files):
        what, where, which records; acknowledged ones too."""
        return service.spool_damage()

    @router.post("/spool/damage/acknowledge", tags=["spool"])
    def acknowledge_spool_damage() -> DamageAckView:
        """Acknowledge every finding awaiting it: health stops reporting ``spool_damage``."""
        return service.acknowledge_spool_damage()

    @router.get("/overlay", tags=["mappings"])
    def get_overlay() -> Overlay:
        """What the admin API changed on top of the config file (saved, applied at start)."""
        return service.overlay
