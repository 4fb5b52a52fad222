"""YAML paths as errors print them and ``--set`` takes them: ``robot_types.tb4.mappings[0].to``.

To name a key holding a dot (or anything but letters, digits, ``_`` and ``-``) in ``--set``,
write it in double quotes: ``kafka.producer_overrides."batch.size"``.
"""

from __future__ import annotations

import re
from collections.abc import Sequence

PathPart = str | int

_SEGMENT = re.compile(r'(?:"(?P<quoted>[^"]+)"|(?P<name>[A-Za-z0-9_\-]+))(?P<indexes>(?:\[\d+\])*)')
_INDEX = re.compile(r"\[(\d+)\]")


def format_path(parts: Sequence[PathPart]) -> str:
    """``("mappings", 0, "to")`` -> ``mappings[0].to``."""
    text = ""
    for part in parts:
        if isinstance(part, int):
            text += f"[{part}]"
        else:
            text += f".{part}" if text else str(part)
    return text or "<root>"


def parse_path(text: str) -> tuple[PathPart, ...]:
    """``a.b[0]."c.d"`` -> ``("a", "b", 0, "c.d")``; raises ValueError on anything else."""
    parts: list[PathPart] = []
    pos = 0
    while True:
        match = _SEGMENT.match(text, pos)
        if match is None:
            raise ValueError(f"expected a YAML path such as spool.dir or mappings[0].to at {text[pos:]!r}")
        parts.append(match.group("quoted") or match.group("name"))
        parts.extend(int(i) for i in _INDEX.findall(match.group("indexes")))
        pos = match.end()
        if pos == len(text):
            return tuple(parts)
        if text[pos] != ".":
            raise ValueError(f"unexpected {text[pos]!r} at {text[pos:]!r}")
        pos += 1
