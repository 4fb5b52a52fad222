"""Interface packages shipped with fleetlink (with their licences): see ``schemas/msgs/README.md``.

rosbags' type stores hold the messages of a distro but no services and no actions. fleetlink
ships the rest of the standard interface packages (``std_srvs``, ``example_interfaces``, the
services of ``rcl_interfaces``, ``common_interfaces`` …, as released for Jazzy) and the iRobot
Create 3 package, so hashes, schemas and the simulator work without ``--msg-path``.
:func:`fleetlink.schemas.typestore.load_typestore` loads every bundled package, except one the
caller brings its own copy of (a package folder of the same name in ``msg_paths``).
"""

from __future__ import annotations

from pathlib import Path

BUNDLED = Path(__file__).resolve().parent / "msgs"

NOT_IN_HUMBLE: frozenset[str] = frozenset(
    {
        # added after Humble: they use messages Humble's store does not have
        "rcl_interfaces/srv/GetLoggerLevels",
        "rcl_interfaces/srv/SetLoggerLevels",
        "type_description_interfaces/srv/GetTypeDescription",
    }
)
"""Interfaces of the bundled packages that the Humble distro does not have."""


def bundled_packages() -> dict[str, Path]:
    """Package name -> folder (each holds ``msg/``, ``srv/`` or ``action/``, its LICENSE)."""
    return {
        p.name: p
        for p in sorted(BUNDLED.iterdir())
        if any((p / kind).is_dir() for kind in ("msg", "srv", "action"))
    }


def bundled_message_paths() -> list[Path]:
    """The folders of every bundled package."""
    return list(bundled_packages().values())


def excluded_interfaces(distro: str) -> frozenset[str]:
    """Bundled interfaces (``pkg/kind/Name``) a distro does not have."""
    return NOT_IN_HUMBLE if distro == "humble" else frozenset()
