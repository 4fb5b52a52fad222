"""Errors of the web console."""

from __future__ import annotations

from fleetlink.common.errors import ConfigError, FleetlinkError


class ConsoleError(FleetlinkError):
    """Something the console cannot do (it is not running, a reply cannot be read)."""


class ConsoleConfigError(ConfigError, ConsoleError):
    """The console's settings cannot be used (its token file cannot be read, is empty)."""


class FormError(ConsoleError):
    """A mapping form the console cannot turn into a request body; ``fields`` maps each form
    field to its messages (``stages``: the YAML text does not parse)."""

    def __init__(self, fields: dict[str, list[str]]) -> None:
        listing = "; ".join(f"{field}: {' '.join(messages)}" for field, messages in sorted(fields.items()))
        super().__init__(f"the form cannot be sent: {listing}")
        self.fields = fields
