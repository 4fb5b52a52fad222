"""The root of every error fleetlink raises on purpose."""


class FleetlinkError(Exception):
    """Base class: catch this to handle any fleetlink error."""


class ConfigError(FleetlinkError):
    """A configuration file or option is invalid; the message names the YAML path."""
