"""The health model every process reports on ``/health``: ok, degraded or failed, and why.

- **ok**: everything works as configured.
- **degraded**: records still flow, but something needs a look (a mapping dead-letters, a
  spool fills up, the WAN link is down and records are being held); each ``Problem`` names the
  component and subject (a mapping, a stream) and a reason code.
- **failed**: the process cannot do its job (its spool cannot be written, Kafka refuses the
  producer); ``/health`` answers HTTP 503 so supervisors and load balancers act on it.

Pure data; what counts as a problem is decided by each component's assessment (for the edge:
``edge.admin.health``).
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass, field
from typing import Any, Literal

State = Literal["ok", "degraded", "failed"]
_RANK: dict[str, int] = {"ok": 0, "degraded": 1, "failed": 2}


@dataclass(frozen=True, slots=True)
class Problem:
    """One thing that keeps a process from being ok: what is affected, why, and how badly."""

    component: str
    """What is affected: ``mapping``, ``spool``, ``wan``, ``kafka``, ``registry``, ``process``."""
    subject: str
    """Which one: the mapping's name, the buffer's stream, the site ..."""
    reason: str
    """A stable code (``unknown_type``, ``dead_letters``, ``spool_filling``, ``wan_down`` ...)."""
    detail: str
    """A sentence for people."""
    severity: Literal["degraded", "failed"] = "degraded"

    def as_dict(self) -> dict[str, str]:
        """The problem as JSON-ready data for ``/health``."""
        return {
            "component": self.component,
            "subject": self.subject,
            "reason": self.reason,
            "detail": self.detail,
            "severity": self.severity,
        }


@dataclass(frozen=True, slots=True)
class Health:
    """A process's health state, the problems behind it and facts to show beside it."""

    state: State
    problems: tuple[Problem, ...] = ()
    extra: dict[str, Any] = field(default_factory=dict)
    """Facts worth showing next to the state (spool fill, robots, link state)."""

    @classmethod
    def of(cls, problems: Iterable[Problem], **extra: Any) -> Health:
        """The worst severity among ``problems`` (``ok`` when there are none)."""
        found = tuple(problems)
        state: State = "ok"
        for problem in found:
            if _RANK[problem.severity] > _RANK[state]:
                state = problem.severity
        return cls(state=state, problems=found, extra=dict(extra))

    @property
    def http_status(self) -> int:
        """200 while the process does its job (ok, degraded), 503 when it failed."""
        return 503 if self.state == "failed" else 200

    def degraded_mappings(self) -> dict[str, list[str]]:
        """Mapping name -> the reasons it is degraded."""
        out: dict[str, list[str]] = {}
        for problem in self.problems:
            if problem.component == "mapping":
                out.setdefault(problem.subject, []).append(problem.reason)
        return out

    def as_dict(self) -> dict[str, Any]:
        """The JSON body of ``/health``: state, degraded mappings, problems and the extra facts."""
        return {
            "state": self.state,
            "degraded_mappings": self.degraded_mappings(),
            "problems": [p.as_dict() for p in self.problems],
            **self.extra,
        }
