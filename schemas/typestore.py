"""The type store: standard types of a ROS 2 distro, custom packages and types embedded in bags.

Built on rosbags' ``Typestore``. Type names are ROS 2 style (``pkg/msg/Name``); the two halves
of a service ``pkg/srv/Name`` are registered as messages ``pkg/srv/Name_Request`` and
``pkg/srv/Name_Response``. Every type referenced by a loaded type must be present: a missing
nested type is an :class:`~schemas.errors.UnknownTypeError` naming it, never a silent skip.
"""

from __future__ import annotations

import re
import xml.etree.ElementTree as ET
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Literal, get_args

from rosbags.interfaces import Nodetype
from rosbags.typesys import Stores, TypesysError, get_types_from_idl, get_types_from_msg, get_typestore

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
    distro: Distro = "jazzy", msg_paths: Sequence[Path] = (), bags: Sequence[Path] = ()
) -> Typestore:
    """Standard types of ``distro`` plus custom packages and the definitions stored in bags.

    ``msg_paths`` are package folders (holding ``msg/*.msg`` and ``srv/*.srv``); ``bags`` are
    rosbag2 directories or files (sqlite3 or MCAP).
    """
    if distro not in _STORES:
        raise TypeDefinitionError(str(distro), "distro", f"unknown distro, expected one of {DISTROS}")
    ts = get_typestore(_STORES[distro])
    for folder in msg_paths:
        register_types(ts, types_from_package(Path(folder)), str(folder))
    for bag in bags:
        register_types(ts, types_from_bag(Path(bag)), str(bag))
    return ts


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


def _split_name(typename: str) -> tuple[str, str, str]:
    parts = typename.split("/")
    if len(parts) != 3 or not all(parts):
        raise TypeDefinitionError(typename, "name", "expected pkg/kind/Name")
    return parts[0], parts[1], parts[2]


def types_from_package(folder: Path) -> Typesdict:
    """Read ``msg/*.msg`` and ``srv/*.srv`` of one ROS package folder."""
    if not folder.is_dir():
        raise TypeDefinitionError(str(folder), "msg path", "not a directory")
    pkg = _package_name(folder)
    out: Typesdict = {}
    for path in sorted((folder / "msg").glob("*.msg")):
        out.update(types_from_msg(_read(path), f"{pkg}/msg/{path.stem}"))
    for path in sorted((folder / "srv").glob("*.srv")):
        out.update(types_from_srv(_read(path), f"{pkg}/srv/{path.stem}"))
    if not out:
        raise TypeDefinitionError(pkg, str(folder), "no msg/*.msg or srv/*.srv files")
    return out


def _package_name(folder: Path) -> str:
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
