"""Name rules shared by every part: ROS names and types, Kafka topics, Zenoh key chunks, host ids.

Pure checks that return the problem with a name (``None`` when it is fine); each part raises its
own error with it, so one rule has one definition wherever the name is read (config, wire, API).
The annotated types (``KeyChunk``, ``Site``, ``KafkaTopic``, ``RosType``, ``RosTopic``,
``NamespaceGlob``) put the same checks on config fields.
"""

from __future__ import annotations

import re
from collections.abc import Callable
from typing import Annotated

from pydantic import AfterValidator, WithJsonSchema

# -- ROS ------------------------------------------------------------------------------------

ROS_SEGMENT = re.compile(r"[A-Za-z_][A-Za-z0-9_]*")
"""One segment of a ROS name (a topic, namespace or node name)."""
_ROS_MSG_TYPE = re.compile(r"[A-Za-z][A-Za-z0-9_]*/msg/[A-Za-z][A-Za-z0-9_]*")
_ROS_SRV_TYPE = re.compile(r"[A-Za-z][A-Za-z0-9_]*/srv/[A-Za-z][A-Za-z0-9_]*")
_ROS_ACTION_TYPE = re.compile(r"[A-Za-z][A-Za-z0-9_]*/action/[A-Za-z][A-Za-z0-9_]*")
_NAMESPACE_GLOB = re.compile(r"/?[A-Za-z0-9_/*?\[\]!-]+")


def ros_segments_problem(segments: list[str]) -> str | None:
    """What is wrong with the segments of a ROS name, or ``None``."""
    for segment in segments:
        if not segment:
            return "empty path segment ('//' or trailing '/')"
        if not ROS_SEGMENT.fullmatch(segment):
            if segment[0].isdigit():
                return f"segment {segment!r} starts with a digit"
            return f"segment {segment!r} has characters other than [A-Za-z0-9_]"
    return None


def ros_topic_problem(name: str) -> str | None:
    """What is wrong with a fully qualified topic or service name (``/a/b``), or ``None``."""
    if not name.startswith("/"):
        return "not fully qualified (must start with '/')"
    if name == "/":
        return "a topic needs at least one segment"
    return ros_segments_problem(name[1:].split("/"))


def ros_type_problem(name: str) -> str | None:
    """What is wrong with a ROS message type (``package/msg/Type``), or ``None``."""
    if _ROS_MSG_TYPE.fullmatch(name) is None:
        return "must look like 'package/msg/Type'"
    return None


def ros_service_type_problem(name: str) -> str | None:
    """What is wrong with a ROS service type (``package/srv/Type``), or ``None``."""
    if _ROS_SRV_TYPE.fullmatch(name) is None:
        return "must look like 'package/srv/Type'"
    return None


def ros_action_type_problem(name: str) -> str | None:
    """What is wrong with a ROS action type (``package/action/Type``), or ``None``."""
    if _ROS_ACTION_TYPE.fullmatch(name) is None:
        return "must look like 'package/action/Type'"
    return None


def namespace_glob_problem(pattern: str) -> str | None:
    """What is wrong with a glob over robot namespaces (``/tb4_*``), or ``None``."""
    if _NAMESPACE_GLOB.fullmatch(pattern) is None:
        return "is not a namespace glob such as '/tb4_*'"
    return None


# -- Zenoh key chunks -----------------------------------------------------------------------

KEY_CHUNK_MAX = 100
"""The longest name fleetlink puts into one key chunk (a mapping, command or edge id)."""
SITE_MAX = 58
"""The longest site name: the edge router's certificate is named ``edge-<site>`` (64 at most)."""
CERT_NAME_MAX = 64
_KEY_CHARS = "letters, digits, '_', '.', '-'"
_KEY_PATH = re.compile(r"[A-Za-z0-9_.-]+(?:/[A-Za-z0-9_.-]+)*")
_KEY_CHUNK = re.compile(r"[A-Za-z0-9_.-]+")
_CERT_NAME = re.compile(r"[A-Za-z0-9][A-Za-z0-9._-]*")


def key_path_problem(name: str) -> str | None:
    """What keeps ``name`` (one or more '/'-separated chunks, as a robot may have) out of a key."""
    if _KEY_PATH.fullmatch(name) is None:
        return f"cannot be used in a key expression: use {_KEY_CHARS} (no wildcards, no empty chunks)"
    return None


def key_chunk_problem(name: str, *, max_length: int = KEY_CHUNK_MAX) -> str | None:
    """What keeps ``name`` from being one key chunk (a site, edge id, mapping or command name)."""
    if _KEY_CHUNK.fullmatch(name) is None or len(name) > max_length:
        return f"must be one key chunk: 1 to {max_length} {_KEY_CHARS} (no '/', no wildcards)"
    return None


def site_problem(site: str) -> str | None:
    """A site is one key chunk that also names certificates, so it starts with a letter or digit."""
    problem = key_chunk_problem(site, max_length=SITE_MAX)
    if problem is None and not site[0].isalnum():
        problem = "must start with a letter or a digit"
    return problem


def cert_name_problem(name: str) -> str | None:
    """What is wrong with a certificate's common name, or ``None``."""
    if _CERT_NAME.fullmatch(name) is None or len(name) > CERT_NAME_MAX:
        return f"use 1-{CERT_NAME_MAX} letters, digits, '.', '_' or '-', starting with a letter or digit"
    return None


def host_id(hostname: str, fallback: str) -> str:
    """A host name made into a key chunk: other characters become '-', at most 64 of them.

    ``fallback`` when nothing is left (the default edge and repeater ids come from here).
    """
    name = re.sub(r"[^A-Za-z0-9_.-]+", "-", hostname).strip("-.")[:64].strip("-.")
    return name or fallback


# -- Kafka ----------------------------------------------------------------------------------

KAFKA_TOPIC_MAX = 249
_KAFKA_CHAR = re.compile(r"[A-Za-z0-9._-]")


def kafka_bad_chars(text: str) -> str:
    """The characters of ``text`` no Kafka topic name may hold, sorted, each once ('' if none)."""
    return "".join(sorted({c for c in text if _KAFKA_CHAR.fullmatch(c) is None}))


def kafka_topic_problem(name: str) -> str | None:
    """Why ``name`` is not a legal Kafka topic name, or ``None`` when it is."""
    if not name:
        return "a Kafka topic name cannot be empty"
    if len(name) > KAFKA_TOPIC_MAX:
        return f"Kafka topic names have at most {KAFKA_TOPIC_MAX} characters, this one has {len(name)}"
    if name in (".", ".."):
        return f"{name!r} is not a legal Kafka topic name"
    bad = kafka_bad_chars(name)
    if bad:
        return f"Kafka topic names use only [a-zA-Z0-9._-]; {bad!r} is not allowed"
    return None


# -- config field types ---------------------------------------------------------------------


def _rule(problem: Callable[[str], str | None], message: Callable[[str, str], str]) -> Callable[[str], str]:
    def check(value: str) -> str:
        why = problem(value)
        if why is not None:
            raise ValueError(message(value, why))
        return value

    return check


def _plain(value: str, why: str) -> str:
    return f"{value!r} {why}"


def _schema(pattern: str, max_length: int | None = None) -> WithJsonSchema:
    """What the OpenAPI document says of a name (the check itself is the ``*_problem`` function)."""
    schema: dict[str, object] = {"type": "string", "pattern": pattern, "minLength": 1}
    if max_length is not None:
        schema["maxLength"] = max_length
    return WithJsonSchema(schema)


KeyChunk = Annotated[
    str, AfterValidator(_rule(key_chunk_problem, _plain)), _schema(r"^[A-Za-z0-9_.-]+$", KEY_CHUNK_MAX)
]
"""A name that is one key chunk (edge id, repeater id, mapping or command name)."""
Site = Annotated[
    str, AfterValidator(_rule(site_problem, _plain)), _schema(r"^[A-Za-z0-9][A-Za-z0-9_.-]*$", SITE_MAX)
]
"""A site: one key chunk of at most 58 characters, starting with a letter or digit."""
KafkaTopic = Annotated[
    str,
    AfterValidator(_rule(kafka_topic_problem, lambda _value, why: why)),
    _schema(r"^[A-Za-z0-9._-]+$", KAFKA_TOPIC_MAX),
]
"""A legal Kafka topic name."""
RosType = Annotated[
    str,
    AfterValidator(_rule(ros_type_problem, lambda value, why: f"ROS type {value!r} {why}")),
    _schema(f"^{_ROS_MSG_TYPE.pattern}$"),
]
"""A ROS message type, ``package/msg/Type``."""

RosServiceType = Annotated[
    str,
    AfterValidator(_rule(ros_service_type_problem, lambda value, why: f"ROS type {value!r} {why}")),
    _schema(f"^{_ROS_SRV_TYPE.pattern}$"),
]
"""A ROS service type, ``package/srv/Type``."""

RosActionType = Annotated[
    str,
    AfterValidator(_rule(ros_action_type_problem, lambda value, why: f"ROS type {value!r} {why}")),
    _schema(f"^{_ROS_ACTION_TYPE.pattern}$"),
]
"""A ROS action type, ``package/action/Type``."""
RosTopic = Annotated[
    str,
    AfterValidator(
        _rule(ros_topic_problem, lambda value, why: f"{value!r} is not an absolute ROS topic name: {why}")
    ),
    _schema(r"^(/[A-Za-z_][A-Za-z0-9_]*)+$"),
]
"""A fully qualified ROS topic name, ``/a/b``."""
NamespaceGlob = Annotated[
    str, AfterValidator(_rule(namespace_glob_problem, _plain)), _schema(f"^{_NAMESPACE_GLOB.pattern}$")
]
"""A glob over robot namespaces, ``/tb4_*``."""
