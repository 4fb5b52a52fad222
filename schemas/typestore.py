"""The type store: standard types of a ROS 2 distro, custom packages and types embedded in bags.

Built on rosbags' ``Typestore`` (the distro's messages), plus the interface packages fleetlink
ships (services and actions of the standard packages, irobot_create_msgs: :mod:`.bundled`).
Type names are ROS 2 style (``pkg/msg/Name``); the two halves of a service ``pkg/srv/Name`` are
registered as messages ``pkg/srv/Name_Request`` and ``pkg/srv/Name_Response``; an action
``pkg/action/Name`` as the messages rosidl makes of it: ``Name_Goal``, ``Name_Result``,
``Name_Feedback``, ``Name_FeedbackMessage`` and the halves of the services ``Name_SendGoal``
and ``Name_GetResult``. Every type referenced by a loaded type must be present: a missing
nested type is an :class:`~schemas.errors.UnknownTypeError` naming it, never a silent skip.
"""

from __future__ import annotations

import functools
import re
import xml.etree.ElementTree as ET
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any, Literal, get_args

from rosbags.interfaces import Nodetype
from rosbags.typesys import Stores, TypesysError, get_types_from_idl, get_types_from_msg, get_typestore

from fleetlink.schemas.bundled import bundled_packages, excluded_interfaces
from fleetlink.schemas.errors import TypeDefinitionError, UnknownTypeError

if TYPE_CHECKING:
    from rosbags.interfaces.typing import Fielddefs, FieldDesc, Typesdict
    from rosbags.typesys.store import Typestore

Distro = Literal["humble", "jazzy", "kilted"]
DISTROS: tuple[Distro, ...] = get_args(Distro)

_STORES: dict[str, Stores] = {
    "humble": Stores.ROS2_HUMBLE,
    "jazzy": Stores.ROS2_JAZZY,
    "kilted": Stores.ROS2_KILTED,
}

# rosidl gives a message without fields this one member (it is on the wire, and in the hash).
EMPTY_MEMBER: tuple[str, FieldDesc] = ("structure_needs_at_least_one_member", (Nodetype.BASE, ("uint8", 0)))

_SRV_SEPARATOR = re.compile(r"^\s*---\s*$", re.MULTILINE)


def load_typestore(
    distro: Distro = "jazzy",
    msg_paths: Sequence[Path] = (),
    bags: Sequence[Path] = (),
    *,
    bundled: bool = True,
) -> Typestore:
    """Standard types of ``distro``, the bundled packages, custom packages and the definitions
    stored in bags.

    ``msg_paths`` are package folders (holding ``msg/*.msg``, ``srv/*.srv``, ``action/*.action``);
    a package given here replaces the bundled package of the same name. ``bags`` are rosbag2
    directories or files (sqlite3 or MCAP).
    """
    if distro not in _STORES:
        raise TypeDefinitionError(str(distro), "distro", f"unknown distro, expected one of {DISTROS}")
    ts = get_typestore(_STORES[distro])
    own = {package_name(Path(folder)) for folder in msg_paths if Path(folder).is_dir()}
    if bundled:
        for name, (folder, types) in _bundled_types(distro).items():
            if name not in own:
                register_types(ts, types, str(folder))
    for folder in msg_paths:
        register_types(ts, types_from_package(Path(folder)), str(folder))
    for bag in bags:
        register_types(ts, types_from_bag(Path(bag)), str(bag))
    return ts


@functools.cache
def _bundled_types(distro: Distro) -> dict[str, tuple[Path, Typesdict]]:
    """The bundled packages' definitions, parsed once per process (registering copies nothing)."""
    skip = excluded_interfaces(distro)
    return {
        name: (folder, types_from_package(folder, skip=skip)) for name, folder in bundled_packages().items()
    }


def message_types(ts: Typestore) -> list[str]:
    """All message type names in the store (service halves included), sorted."""
    return sorted(ts.fielddefs)


def normalize_typename(name: str) -> str:
    """``pkg/Name`` -> ``pkg/msg/Name``; names that already carry an interface kind are kept."""
    parts = name.strip("/").split("/")
    if len(parts) == 2:
        return f"{parts[0]}/msg/{parts[1]}"
    return "/".join(parts)


def fields_of(ts: Typestore, typename: str, referenced_by: str | None = None) -> Fielddefs:
    """The fields of a message type, raising :class:`UnknownTypeError` if it is not in the store."""
    entry = ts.fielddefs.get(typename)
    if entry is None:
        raise UnknownTypeError(typename, referenced_by)
    return entry[1]


def nested_name(desc: FieldDesc) -> str | None:
    """The nested type a field refers to (directly or as array/sequence element), if any."""
    if desc[0] == Nodetype.NAME:
        return desc[1]
    if desc[0] in (Nodetype.ARRAY, Nodetype.SEQUENCE):
        inner = desc[1][0]
        if inner[0] == Nodetype.NAME:
            return inner[1]
    return None


def check_references(ts: Typestore, typename: str) -> None:
    """Raise :class:`UnknownTypeError` for the first type reachable from ``typename`` that is missing."""
    seen: set[str] = set()
    pending: list[tuple[str, str | None]] = [(typename, None)]
    while pending:
        name, parent = pending.pop()
        if name in seen:
            continue
        seen.add(name)
        for fname, desc in fields_of(ts, name, parent):
            sub = nested_name(desc)
            if sub is not None:
                pending.append((sub, f"{name}.{fname}"))


def register_types(ts: Typestore, types: Typesdict, source: str) -> None:
    """Add ``types`` to ``ts``; conflicts and dangling references are errors naming the type."""
    try:
        ts.register(types)
    except TypesysError as exc:
        raise TypeDefinitionError(_first_conflict(ts, types), source, str(exc)) from exc
    for name in sorted(types):
        check_references(ts, name)


def _first_conflict(ts: Typestore, types: Typesdict) -> str:
    for name in sorted(types):
        have = ts.fielddefs.get(name)
        if have is not None and [(f.lower(), d) for f, d in have[1]] != [
            (f.lower(), d) for f, d in types[name][1]
        ]:
            return name
    return ",".join(sorted(types))


def types_from_msg(text: str, typename: str) -> Typesdict:
    """Parse one ``.msg`` definition (or a rosbag2-style bundle) registered as ``typename``."""
    try:
        types = get_types_from_msg(text, typename)
    except TypesysError as exc:
        raise TypeDefinitionError(typename, "msg", str(exc)) from exc
    return {name: (consts, fields or [EMPTY_MEMBER]) for name, (consts, fields) in types.items()}


def types_from_srv(text: str, typename: str) -> Typesdict:
    """Parse a ``.srv`` definition of ``pkg/srv/Name`` into ``Name_Request`` and ``Name_Response``."""
    pkg, kind, name = _split_name(typename)
    if kind != "srv":
        raise TypeDefinitionError(typename, "srv", "a service type name looks like pkg/srv/Name")
    halves = _SRV_SEPARATOR.split(text)
    if len(halves) != 2:
        raise TypeDefinitionError(typename, "srv", "expected exactly one '---' line")
    out: Typesdict = {}
    for suffix, half in zip(("Request", "Response"), halves, strict=True):
        # Parsed as pkg/msg/... so short nested names resolve into pkg/msg, then renamed.
        parsed = types_from_msg(half, f"{pkg}/msg/{name}_{suffix}")
        out[f"{pkg}/srv/{name}_{suffix}"] = parsed.pop(f"{pkg}/msg/{name}_{suffix}")
        out.update(parsed)
    return out


def types_from_action(text: str, typename: str) -> Typesdict:
    """Parse a ``.action`` definition of ``pkg/action/Name`` into the messages rosidl makes of it."""
    pkg, kind, name = _split_name(typename)
    if kind != "action":
        raise TypeDefinitionError(typename, "action", "an action type name looks like pkg/action/Name")
    parts = _SRV_SEPARATOR.split(text)
    if len(parts) != 3:
        raise TypeDefinitionError(typename, "action", "expected exactly two '---' lines")
    out: Typesdict = {}
    for suffix, part in zip(("Goal", "Result", "Feedback"), parts, strict=True):
        parsed = types_from_msg(part, f"{pkg}/msg/{name}_{suffix}")
        out[f"{typename}_{suffix}"] = parsed.pop(f"{pkg}/msg/{name}_{suffix}")
        out.update(parsed)
    uuid = (Nodetype.NAME, "unique_identifier_msgs/msg/UUID")

    def message(*fields: tuple[str, Any]) -> Any:  # rosbags' (constants, fields) pair
        return [], list(fields)

    out[f"{typename}_SendGoal_Request"] = message(
        ("goal_id", uuid), ("goal", (Nodetype.NAME, f"{typename}_Goal"))
    )
    out[f"{typename}_SendGoal_Response"] = message(
        ("accepted", (Nodetype.BASE, ("bool", 0))),
        ("stamp", (Nodetype.NAME, "builtin_interfaces/msg/Time")),
    )
    out[f"{typename}_GetResult_Request"] = message(("goal_id", uuid))
    out[f"{typename}_GetResult_Response"] = message(
        ("status", (Nodetype.BASE, ("int8", 0))), ("result", (Nodetype.NAME, f"{typename}_Result"))
    )
    out[f"{typename}_FeedbackMessage"] = message(
        ("goal_id", uuid), ("feedback", (Nodetype.NAME, f"{typename}_Feedback"))
    )
    return out


def _split_name(typename: str) -> tuple[str, str, str]:
    parts = typename.split("/")
    if len(parts) != 3 or not all(parts):
        raise TypeDefinitionError(typename, "name", "expected pkg/kind/Name")
    return parts[0], parts[1], parts[2]


_READERS = (("msg", types_from_msg), ("srv", types_from_srv), ("action", types_from_action))


def types_from_package(folder: Path, *, skip: frozenset[str] = frozenset()) -> Typesdict:
    """Read ``msg/*.msg``, ``srv/*.srv`` and ``action/*.action`` of one ROS package folder,
    leaving out the interfaces (``pkg/kind/Name``) in ``skip``."""
    if not folder.is_dir():
        raise TypeDefinitionError(str(folder), "msg path", "not a directory")
    pkg = package_name(folder)
    out: Typesdict = {}
    found = False
    for kind, reader in _READERS:
        for path in sorted((folder / kind).glob(f"*.{kind}")):
            found = True
            name = f"{pkg}/{kind}/{path.stem}"
            if name not in skip:
                out.update(reader(_read(path), name))
    if not found:
        inside = sorted(
            p.name for p in folder.iterdir() if p.is_dir() and p.name not in ("msg", "srv", "action")
        )
        hint = ""
        if any((folder / sub / kind).is_dir() for sub in inside for kind in ("msg", "srv", "action")):
            hint = f"; it holds packages ({', '.join(inside)}): give each package's folder instead"
        raise TypeDefinitionError(pkg, str(folder), f"no msg/*.msg, srv/*.srv or action/*.action files{hint}")
    return out


def package_name(folder: Path) -> str:
    """The package's name: ``<name>`` of its package.xml, else the folder's name."""
    manifest = folder / "package.xml"
    if manifest.is_file():
        try:
            name = ET.fromstring(_read(manifest)).findtext("name")  # noqa: S314 (local file)
        except ET.ParseError as exc:
            raise TypeDefinitionError(folder.name, str(manifest), str(exc)) from exc
        if name and name.strip():
            return name.strip()
    return folder.name


def _read(path: Path) -> str:
    try:
        return path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise TypeDefinitionError(path.stem, str(path), str(exc)) from exc


def types_from_bag(path: Path) -> Typesdict:
    """The message definitions embedded in a rosbag2 bag (sqlite3 or MCAP storage)."""
    from rosbags.interfaces import MessageDefinitionFormat
    from rosbags.rosbag2 import Reader, ReaderError

    out: Typesdict = {}
    try:
        with Reader(path) as reader:
            for conn in reader.connections:
                msgdef = conn.msgdef
                if msgdef is None or not msgdef.data:
                    raise TypeDefinitionError(conn.msgtype, str(path), "bag stores no definition")
                if msgdef.format == MessageDefinitionFormat.IDL:
                    out.update(_types_from_idl(msgdef.data, conn.msgtype, path))
                else:
                    out.update(types_from_msg(msgdef.data, conn.msgtype))
    except ReaderError as exc:
        raise TypeDefinitionError("?", str(path), f"cannot read bag: {exc}") from exc
    return out


def _types_from_idl(text: str, typename: str, path: Path) -> Typesdict:
    try:
        return get_types_from_idl(text)
    except TypesysError as exc:
        raise TypeDefinitionError(typename, str(path), str(exc)) from exc
