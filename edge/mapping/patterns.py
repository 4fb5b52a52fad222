"""ROS topic patterns with captures: ``/{robot}/imu``, ``/{robot}/{sensor}``, ``/{robot}/{rest*}``.

A pattern is an absolute ROS name whose segments are either literal (``imu``) or a capture:
``{name}`` takes exactly one segment, ``{name*}`` takes one or more (at most one such capture
per pattern). Captures are whole segments only. Matching is a compiled regular expression;
``bind`` turns captures into literals (a robot type's ``{robot}`` becomes the robot's name).
"""

from __future__ import annotations

import re
from collections.abc import Mapping
from dataclasses import dataclass

from fleetlink.edge.errors import MappingError

IDENTIFIER = re.compile(r"[A-Za-z_][A-Za-z0-9_]*")
_LITERAL_SEGMENT = re.compile(r"[A-Za-z0-9_]+")
_CAPTURE_SEGMENT = re.compile(r"\{([A-Za-z_][A-Za-z0-9_]*)(\*?)\}")

RESERVED_NAMES = frozenset({"msg"})
"""``msg`` starts a message-field path in templates, so it cannot name a capture."""


@dataclass(frozen=True, slots=True)
class Capture:
    """A capture segment: ``{name}`` (one segment) or ``{name*}`` (one or more)."""

    name: str
    multi: bool = False

    def text(self) -> str:
        """The capture as written in a pattern: ``{name}`` or ``{name*}``."""
        return "{" + self.name + ("*" if self.multi else "") + "}"


Segment = str | Capture


def _segment_regex(segment: Segment) -> str:
    if isinstance(segment, str):
        return re.escape(segment)
    if segment.multi:
        return f"(?P<{segment.name}>[^/]+(?:/[^/]+)*)"
    return f"(?P<{segment.name}>[^/]+)"


@dataclass(frozen=True, slots=True)
class TopicPattern:
    """A parsed, validated topic pattern. Build with ``TopicPattern.parse``."""

    text: str
    segments: tuple[Segment, ...]
    regex: re.Pattern[str]

    @classmethod
    def parse(cls, text: str, *, mapping: str | None = None) -> TopicPattern:
        """Parse ``text``; raises ``MappingError`` naming the mapping and the bad segment."""

        def fail(reason: str) -> MappingError:
            return MappingError(f"topic pattern {text!r}: {reason}", mapping=mapping, template=text)

        if not text.startswith("/") or text == "/":
            raise fail("must be an absolute ROS name such as '/{robot}/imu'")
        if text.endswith("/"):
            raise fail("must not end with '/'")
        segments: list[Segment] = []
        seen: set[str] = set()
        for raw in text[1:].split("/"):
            if raw == "":
                raise fail("empty segment ('//')")
            capture = _CAPTURE_SEGMENT.fullmatch(raw)
            if capture is not None:
                name, star = capture.group(1), capture.group(2)
                if name in RESERVED_NAMES:
                    raise fail(f"{{{name}}} is reserved for message fields; pick another capture name")
                if name in seen:
                    raise fail(f"capture {{{name}}} appears twice")
                if star and any(isinstance(s, Capture) and s.multi for s in segments):
                    raise fail("at most one multi-segment capture ({name*}) per pattern")
                seen.add(name)
                segments.append(Capture(name, multi=bool(star)))
            elif "{" in raw or "}" in raw:
                raise fail(f"segment {raw!r}: a capture must be a whole segment such as '{{sensor}}'")
            elif _LITERAL_SEGMENT.fullmatch(raw) is None:
                raise fail(f"segment {raw!r}: ROS names use letters, digits and '_' only")
            else:
                segments.append(raw)
        return cls._build(text, tuple(segments))

    @classmethod
    def _build(cls, text: str, segments: tuple[Segment, ...]) -> TopicPattern:
        body = "".join("/" + _segment_regex(s) for s in segments)
        return cls(text=text, segments=segments, regex=re.compile(body))

    @property
    def captures(self) -> tuple[str, ...]:
        """Capture names, in order of appearance."""
        return tuple(s.name for s in self.segments if isinstance(s, Capture))

    @property
    def is_literal(self) -> bool:
        """True when the pattern has no captures left (it names exactly one topic)."""
        return all(isinstance(s, str) for s in self.segments)

    def is_single(self, name: str) -> bool:
        """True when ``name`` is a one-segment capture of this pattern."""
        return any(isinstance(s, Capture) and s.name == name and not s.multi for s in self.segments)

    def match(self, topic: str) -> dict[str, str] | None:
        """The captured values when ``topic`` matches the whole pattern, else ``None``."""
        found = self.regex.fullmatch(topic)
        if found is None:
            return None
        return found.groupdict()

    def bind(self, values: Mapping[str, str]) -> TopicPattern:
        """Replace the named captures by literal text (which may span several segments)."""
        segments: list[Segment] = []
        for segment in self.segments:
            if isinstance(segment, Capture) and segment.name in values:
                segments.extend(p for p in values[segment.name].strip("/").split("/") if p)
            else:
                segments.append(segment)
        text = "/" + "/".join(s if isinstance(s, str) else s.text() for s in segments)
        return self._build(text, tuple(segments))


def check_robot_name(name: str) -> str:
    """A robot name is its namespace without the leading '/': ``tb4_01`` or ``fleet/tb4_01``.
    Returns the normalised name; raises ``MappingError`` when it is not a valid ROS namespace."""
    stripped = name.strip("/")
    parts = stripped.split("/") if stripped else []
    if not parts or any(_LITERAL_SEGMENT.fullmatch(p) is None for p in parts):
        raise MappingError(f"robot name {name!r} is not a ROS namespace (letters, digits, '_', '/')")
    return stripped
