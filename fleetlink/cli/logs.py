"""How the ``fleetlink`` command logs: quiet tools, talkative services, text or JSON lines.

Tools (``ros graph``, ``validate`` …) print their results and log only warnings; services
(``edge run``, ``uplink run``, ``repeater run``, ``zenoh router``) log what they do (INFO). Each
``-v`` adds a level. ``--log-format json`` writes one JSON object per line for log collectors.
Warnings that dependencies raise about themselves (deprecations) go to the log at DEBUG, so
they reach a user only with ``-vv``.
"""

from __future__ import annotations

import json
import logging
import sys
import warnings
from typing import Any

_HANDLER = "fleetlink-cli"
SERVICE_VERBOSITY = 1
"""What ``set_defaults(log_verbosity=SERVICE_VERBOSITY)`` gives a long-running service: INFO."""


class JsonFormatter(logging.Formatter):
    """Formats each log record as one JSON object: time, level, logger, message and any traceback."""

    def format(self, record: logging.LogRecord) -> str:
        """The record as one line of JSON (non-ASCII text kept as is)."""
        entry: dict[str, Any] = {
            "ts": self.formatTime(record, "%Y-%m-%dT%H:%M:%S") + f".{int(record.msecs):03d}",
            "level": record.levelname.lower(),
            "logger": record.name,
            "message": record.getMessage(),
        }
        if record.exc_info:
            entry["exception"] = self.formatException(record.exc_info)
        return json.dumps(entry, ensure_ascii=False)


def level_for(verbosity: int) -> int:
    """0: WARNING, 1: INFO, 2 and more: DEBUG."""
    return (logging.WARNING, logging.INFO, logging.DEBUG)[max(0, min(verbosity, 2))]


def configure_logging(verbosity: int, log_format: str = "text") -> None:
    """Send log lines to standard error at the level of ``verbosity``, as ``text`` or ``json``.

    Replaces the handler an earlier call installed, and routes Python warnings to the log at DEBUG.
    """
    handler = logging.StreamHandler(sys.stderr)
    if log_format == "json":
        handler.setFormatter(JsonFormatter())
    else:
        handler.setFormatter(logging.Formatter("%(asctime)s %(levelname)s %(name)s: %(message)s"))
    handler.set_name(_HANDLER)
    root = logging.getLogger()
    for old in [h for h in root.handlers if h.get_name() == _HANDLER]:
        root.removeHandler(old)  # ours from an earlier call (tests call main() many times)
    root.addHandler(handler)
    root.setLevel(level_for(verbosity))
    if verbosity < 2:
        logging.getLogger("httpx").setLevel(logging.WARNING)
    # Dependencies' own warnings (e.g. a deprecation inside the Kafka client's extras) are
    # logged at DEBUG: some libraries force "always" filters, so routing beats filtering.
    warnings.showwarning = _warning_to_log


def _warning_to_log(  # noqa: PLR0917 - the signature of warnings.showwarning
    message: Warning | str,
    category: type[Warning],
    filename: str,
    lineno: int,
    file: Any = None,  # noqa: ARG001 - always the log here
    line: str | None = None,
) -> None:
    text = warnings.formatwarning(message, category, filename, lineno, line).strip()
    logger = logging.getLogger("py.warnings")
    from_dependency = "site-packages" in filename or "dist-packages" in filename
    logger.log(logging.DEBUG if from_dependency else logging.WARNING, "%s", text)
