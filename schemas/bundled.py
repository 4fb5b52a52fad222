"""Message packages shipped with fleetlink (with their licences), for the simulator and demo."""

from __future__ import annotations

from pathlib import Path

BUNDLED = Path(__file__).resolve().parent / "msgs"


def bundled_message_paths() -> list[Path]:
    """Package folders under ``schemas/msgs`` (each holds ``msg/``, ``srv/``, its LICENSE)."""
    return sorted(p for p in BUNDLED.iterdir() if (p / "msg").is_dir())
