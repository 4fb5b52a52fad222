"""Errors of the admin API. Each carries the HTTP status it maps to (the Zenoh admin space uses
the same codes in its reply envelope)."""

from __future__ import annotations

from dataclasses import dataclass

from fleetlink.common.errors import ConfigError
from fleetlink.edge.errors import EdgeError


@dataclass(frozen=True, slots=True)
class FieldProblem:
    """One validation problem: ``path`` in the request body (``stages[1].hz``), ``config_path``
    where it lands in the effective edge config (``robot_types.tb4.mappings[2].stages[1].hz``)."""

    path: str
    message: str
    config_path: str | None = None

    def as_dict(self) -> dict[str, str | None]:
        """The problem as a JSON-ready dict (``path``, ``message``, ``config_path``)."""
        return {"path": self.path, "message": self.message, "config_path": self.config_path}


class AdminError(EdgeError):
    """A request the admin API refuses; ``status`` is its HTTP status."""

    status = 400


class NotFoundError(AdminError):
    """No mapping or robot type of that name exists."""

    status = 404


class ConflictError(AdminError):
    """The change clashes with what exists (a mapping of that name exists already)."""

    status = 409


class InvalidChangeError(AdminError):
    """The change would make an invalid config; nothing was applied. ``problems`` name each field."""

    status = 422

    def __init__(self, message: str, problems: tuple[FieldProblem, ...]) -> None:
        listing = "; ".join(f"{p.path}: {p.message}" for p in problems)
        super().__init__(f"{message}: {listing}" if listing else message)
        self.summary = message
        self.problems = problems


class UnauthorizedError(AdminError):
    """The request carries no admin token or a wrong one."""

    status = 401


class ForbiddenError(AdminError):
    """The caller may not make this request, whatever token it carries."""

    status = 403


class TooManyAttemptsError(AdminError):
    """Too many wrong tokens from this client: it must wait ``retry_after`` seconds."""

    status = 429

    def __init__(self, retry_after: float) -> None:
        super().__init__(f"too many wrong tokens: try again in {retry_after:.0f} s")
        self.retry_after = retry_after


class PersistError(AdminError):
    """The overlay file could not be written; the change was not applied."""

    status = 503


class OverlayError(ConfigError, EdgeError):
    """The persisted overlay cannot be read or no longer fits the config file (at start)."""


class TokenError(ConfigError, EdgeError):
    """The admin token file cannot be read or is empty."""
