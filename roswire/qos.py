"""ROS 2 QoS profiles and rmw_zenoh's compact QoS string (rmw_zenoh.md §3).

``<rel>:<dur>:<hist>,<depth>:<dl_s>,<dl_ns>:<ls_s>,<ls_ns>:<liv>,<lease_s>,<lease_ns>``; every
field equal to rmw_zenoh's default (RELIABLE, VOLATILE, KEEP_LAST, depth 42, infinite durations,
AUTOMATIC) is written empty. Enum numbers are rmw's.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from enum import IntEnum
from typing import Any, TypeVar

from fleetlink.roswire.errors import QosParseError

E = TypeVar("E", bound=IntEnum)


class Reliability(IntEnum):
    """Reliability policy: retransmit lost samples or not (rmw numbering)."""

    SYSTEM_DEFAULT = 0
    RELIABLE = 1
    BEST_EFFORT = 2
    UNKNOWN = 3
    BEST_AVAILABLE = 4


class Durability(IntEnum):
    """Durability policy: whether late joiners get cached samples (rmw numbering)."""

    SYSTEM_DEFAULT = 0
    TRANSIENT_LOCAL = 1
    VOLATILE = 2
    UNKNOWN = 3
    BEST_AVAILABLE = 4


class History(IntEnum):
    """History policy: keep the last ``depth`` samples or all (rmw numbering)."""

    SYSTEM_DEFAULT = 0
    KEEP_LAST = 1
    KEEP_ALL = 2
    UNKNOWN = 3


class Liveliness(IntEnum):
    """Liveliness policy: how an entity shows it is alive (rmw numbering)."""

    SYSTEM_DEFAULT = 0
    AUTOMATIC = 1
    MANUAL_BY_NODE = 2
    MANUAL_BY_TOPIC = 3
    UNKNOWN = 4
    BEST_AVAILABLE = 5


@dataclass(frozen=True)
class Duration:
    """An rmw_time_t: seconds and nanoseconds kept apart, as on the wire."""

    sec: int
    nsec: int

    @property
    def is_infinite(self) -> bool:
        """Whether this is RMW_DURATION_INFINITE."""
        return self == INFINITE

    def to_ns(self) -> int:
        """The duration in nanoseconds."""
        return self.sec * 1_000_000_000 + self.nsec


INFINITE = Duration(9223372036, 854775807)
"""RMW_DURATION_INFINITE, the default deadline, lifespan and lease."""

ZENOH_DEFAULT_DEPTH = 42
"""rmw_zenoh's default history depth: a depth of 42 is written as an empty field."""


@dataclass(frozen=True)
class QoS:
    """A ROS 2 QoS profile; the defaults are ``rclcpp::QoS(10)``."""

    reliability: Reliability = Reliability.RELIABLE
    durability: Durability = Durability.VOLATILE
    history: History = History.KEEP_LAST
    depth: int = 10
    deadline: Duration = INFINITE
    lifespan: Duration = INFINITE
    liveliness: Liveliness = Liveliness.AUTOMATIC
    lease: Duration = INFINITE

    @property
    def transient_local(self) -> bool:
        """Whether late joiners get the publisher's cached samples."""
        return self.durability == Durability.TRANSIENT_LOCAL

    @property
    def best_effort(self) -> bool:
        """Whether samples may be dropped rather than retransmitted."""
        return self.reliability == Reliability.BEST_EFFORT

    def with_depth(self, depth: int) -> QoS:
        """The same profile with history depth ``depth``."""
        return replace(self, depth=depth)

    def to_keyexpr(self) -> str:
        """The compact string rmw_zenoh puts in endpoint tokens (defaults elided)."""

        def field(value: int, default: int) -> str:
            return "" if value == default else str(value)

        def duration(value: Duration) -> str:
            return f"{field(value.sec, INFINITE.sec)},{field(value.nsec, INFINITE.nsec)}"

        return ":".join(
            (
                field(self.reliability, Reliability.RELIABLE),
                field(self.durability, Durability.VOLATILE),
                f"{field(self.history, History.KEEP_LAST)},{field(self.depth, ZENOH_DEFAULT_DEPTH)}",
                duration(self.deadline),
                duration(self.lifespan),
                f"{field(self.liveliness, Liveliness.AUTOMATIC)},{duration(self.lease)}",
            )
        )

    @classmethod
    def parse(cls, text: str) -> QoS:
        """Parse a compact QoS string; empty fields take rmw_zenoh's defaults.

        Like rmw_zenoh's ``keyexpr_to_qos``, at least 6 ``:``-separated fields are required, with
        at least 1/1/2/2/2/3 ``,``-separated sub-fields; extra fields and sub-fields are ignored.
        """
        fields = text.split(":")
        if len(fields) < 6:
            raise QosParseError(text, f"needs 6 ':'-separated fields, has {len(fields)}")
        rel, dur, hist, deadline, lifespan, liv = fields[:6]
        hist_parts = _parts(text, "history", hist, 2)
        live_parts = _parts(text, "liveliness", liv, 3)
        return cls(
            reliability=_enum(text, "reliability", Reliability, rel, Reliability.RELIABLE),
            durability=_enum(text, "durability", Durability, dur, Durability.VOLATILE),
            history=_enum(text, "history", History, hist_parts[0], History.KEEP_LAST),
            depth=_int(text, "depth", hist_parts[1], ZENOH_DEFAULT_DEPTH),
            deadline=_duration(text, "deadline", deadline),
            lifespan=_duration(text, "lifespan", lifespan),
            liveliness=_enum(text, "liveliness", Liveliness, live_parts[0], Liveliness.AUTOMATIC),
            lease=_duration(text, "lease", ",".join(live_parts[1:])),
        )


def _parts(text: str, what: str, field: str, count: int) -> list[str]:
    parts = field.split(",")
    if len(parts) < count:
        raise QosParseError(text, f"{what} field {field!r} needs {count} ','-separated parts")
    return parts[:count]


def _int(text: str, what: str, raw: str, default: int) -> int:
    if raw == "":
        return default
    if not raw.isascii() or not raw.isdigit():
        raise QosParseError(text, f"{what} {raw!r} is not a non-negative integer")
    return int(raw)


def _enum(text: str, what: str, enum: type[E], raw: str, default: E) -> E:
    value = _int(text, what, raw, int(default))
    try:
        return enum(value)
    except ValueError:
        raise QosParseError(text, f"{what} {value} is not a known value") from None


def _duration(text: str, what: str, field: str) -> Duration:
    sec, nsec = _parts(text, what, field, 2)
    return Duration(_int(text, what, sec, INFINITE.sec), _int(text, what, nsec, INFINITE.nsec))


DEFAULT = QoS()
"""``rclcpp::QoS(10)``: reliable, volatile, keep last 10 -> ``::,10:,:,:,,``."""

SENSOR_DATA = QoS(reliability=Reliability.BEST_EFFORT, depth=5)
"""``rclcpp::SensorDataQoS()``: best effort, depth 5 -> ``2::,5:,:,:,,``."""

TRANSIENT_LOCAL = QoS(durability=Durability.TRANSIENT_LOCAL, depth=1)
"""Latched topics such as ``/tf_static``: reliable, transient local, depth 1 -> ``:1:,1:,:,:,,``."""

SERVICES = QoS()
"""Services and clients: ``::,10:,:,:,,``."""


# --- readable form (``fleetlink ros graph``, ``--qos``) ---------------------------------------

PROFILES: dict[str, QoS] = {
    "default": DEFAULT,
    "sensor_data": SENSOR_DATA,
    "transient_local": TRANSIENT_LOCAL,
    "services": SERVICES,
}
"""Named profiles ``--qos`` takes, as rclcpp names them."""

_WORDS: dict[str, dict[str, Any]] = {
    "reliable": {"reliability": Reliability.RELIABLE},
    "best_effort": {"reliability": Reliability.BEST_EFFORT},
    "volatile": {"durability": Durability.VOLATILE},
    "transient_local": {"durability": Durability.TRANSIENT_LOCAL},
    "keep_all": {"history": History.KEEP_ALL},
}


def _seconds(value: Duration) -> str:
    return f"{value.to_ns() / 1e9:g}s"


def describe(qos: QoS) -> str:
    """``reliable, volatile, keep_last 10`` (plus deadline, lifespan, liveliness when set)."""
    parts = [qos.reliability.name.lower(), qos.durability.name.lower()]
    parts.append(f"keep_last {qos.depth}" if qos.history == History.KEEP_LAST else qos.history.name.lower())
    if not qos.deadline.is_infinite:
        parts.append(f"deadline {_seconds(qos.deadline)}")
    if not qos.lifespan.is_infinite:
        parts.append(f"lifespan {_seconds(qos.lifespan)}")
    if qos.liveliness != Liveliness.AUTOMATIC or not qos.lease.is_infinite:
        lease = "" if qos.lease.is_infinite else f" {_seconds(qos.lease)}"
        parts.append(f"liveliness {qos.liveliness.name.lower()}{lease}")
    return ", ".join(parts)


def parse_profile(text: str) -> QoS:
    """A named profile (``sensor_data``) or words as :func:`describe` writes them, e.g.
    ``best_effort, transient_local, keep_last 5``; what is not said stays as in ``default``."""
    name = text.strip().lower()
    if name in PROFILES:
        return PROFILES[name]
    qos = DEFAULT
    for raw in name.split(","):
        words = raw.split()
        if not words:
            continue
        if words[0] in ("keep_last", "depth") and len(words) == 2 and words[1].isdigit():
            qos = replace(qos, history=History.KEEP_LAST, depth=int(words[1]))
        elif len(words) == 1 and words[0] in _WORDS:
            qos = replace(qos, **_WORDS[words[0]])
        else:
            known = ", ".join([*PROFILES, *_WORDS, "keep_last N"])
            raise QosParseError(text, f"{raw.strip()!r} is not a QoS setting (known: {known})")
    return qos


def adapted(publishers: list[QoS]) -> QoS:
    """What a subscriber should ask for to hear every one of these publishers, as ``ros2 topic
    echo`` adapts: best effort if any publisher is, transient local only if all are."""
    if not publishers:
        return DEFAULT
    reliability = Reliability.BEST_EFFORT if any(q.best_effort for q in publishers) else Reliability.RELIABLE
    durability = (
        Durability.TRANSIENT_LOCAL if all(q.transient_local for q in publishers) else Durability.VOLATILE
    )
    depth = max(q.depth for q in publishers) if durability == Durability.TRANSIENT_LOCAL else DEFAULT.depth
    return replace(DEFAULT, reliability=reliability, durability=durability, depth=depth)
