"""Optional parts of fleetlink and the pip extras that bring their packages.

``pip install fleetlink`` is what an edge device needs. The web console (``console``: its page
templates) and the demo (``demo``: its stream-processing app) are extras; importing one of
their modules without its packages raises ``MissingExtraError`` saying what to install.
"""

from __future__ import annotations

from fleetlink.common.errors import FleetlinkError

EXTRAS: dict[str, str] = {
    "console": "the web console",
    "demo": "the demo's fault-detection stream app",
}
"""The extras, and what each one adds."""


class MissingExtraError(FleetlinkError, ImportError):
    """A part of fleetlink was used whose optional packages are not installed."""

    def __init__(self, extra: str, package: str) -> None:
        super().__init__(
            f"{EXTRAS[extra]} needs the package {package!r}, which is not installed: "
            f"pip install 'fleetlink[{extra}]'"
        )
        self.extra = extra
        self.package = package


def missing_extra(exc: ModuleNotFoundError, extra: str) -> MissingExtraError:
    """The error to raise for ``exc``, an import of one of ``extra``'s packages that failed."""
    return MissingExtraError(extra, (exc.name or "?").split(".")[0])
