"""``project``: keep only chosen fields; the output has a derived Avro schema.

Two layouts:

* nested (default): the message structure is kept, pruned to the chosen paths
  (``[header.stamp, twist.twist.linear.x]`` -> ``{header: {stamp}, twist: {twist: {linear: {x}}}}``);
  paths cannot index arrays, and no path may lie inside another;
* ``flatten: true``: one top-level field per path, named with ``_`` for dots and brackets
  (``twist_twist_linear_x``, ``ranges_0``); array elements are allowed.

The derived record is named ``<namespace>.<Name>_proj_<hash>`` where the hash covers the paths
and the layout, so the same projection of the same type always gets the same schema; nested
records inside it are ``<Name>_proj_<hash>_<path>``. A chosen field that is itself a record
keeps its whole (self-contained) type.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

from fleetlink.edge.stages.avro import (
    Node,
    SchemaIndex,
    copy_self_contained,
    resolve_path,
    root_node,
    short_hash,
)
from fleetlink.edge.stages.base import Sample, StageCounters
from fleetlink.edge.stages.errors import FieldPathError, StageConfigError
from fleetlink.edge.stages.paths import Getter, Steps, field_name, make_getter, parse_path, path_text

_SAMPLE_ERRORS = (LookupError, TypeError)

# nested layout: (field, None) keeps the whole field; (field, subtree) descends into it
Tree = list[tuple[str, "Tree | None"]]


def _build_tree(paths: Sequence[Steps]) -> Tree:
    tree: Tree = []
    for steps in paths:
        level = tree
        for depth, step in enumerate(steps):
            if not isinstance(step, str):
                raise FieldPathError(
                    f"project: {path_text(steps)!r} indexes an array; use flatten: true to keep single "
                    "elements",
                    path=path_text(steps),
                )
            last = depth == len(steps) - 1
            entry = next((e for e in level if e[0] == step), None)
            if entry is None:
                sub: Tree | None = None if last else []
                level.append((step, sub))
                if sub is None:
                    break
                level = sub
            elif entry[1] is None or last:
                raise StageConfigError(
                    f"project: paths overlap at {path_text(steps[: depth + 1])!r}: keep either the whole "
                    "field or parts of it"
                )
            else:
                level = entry[1]
    return tree


def _pick(tree: Tree, value: Mapping[str, Any]) -> dict[str, Any]:
    return {name: value[name] if sub is None else _pick(sub, value[name]) for name, sub in tree}


def _declared(index: SchemaIndex, root: Node, steps: Steps) -> tuple[Node, dict[str, Any]]:
    """The declared type of the field at ``steps`` (nullable unions kept) and its other attributes."""
    leaf = resolve_path(index, root, steps)  # raises a precise error for a bad path
    if isinstance(steps[-1], int):
        return leaf, {}
    parent = resolve_path(index, root, steps[:-1]) if len(steps) > 1 else root
    field = next(f for f in parent.schema["fields"] if f["name"] == steps[-1])
    extra = {k: v for k, v in field.items() if k not in ("name", "type", "aliases")}
    return index.resolve(field["type"], parent.namespace), extra


class ProjectStage:
    """Keeps only the chosen field paths, nested as in the message or flattened to top-level fields."""

    def __init__(self, fields: Sequence[str], *, flatten: bool = False, name: str = "project") -> None:
        if not fields:
            raise StageConfigError("project needs at least one field")
        self.name = name
        self.fields = tuple(fields)
        self.flatten = flatten
        self.counters = StageCounters()
        self.last_error: str | None = None
        self._paths = [parse_path(f) for f in fields]
        if len({path_text(p) for p in self._paths}) != len(self._paths):
            raise StageConfigError(f"project: a field is listed twice in {list(fields)}")
        self._names = [field_name(p) for p in self._paths]
        self._getters: list[tuple[str, Getter]] = []
        self._tree: Tree = []
        if flatten:
            if len(set(self._names)) != len(self._names):
                raise StageConfigError(f"project: flattened field names collide: {self._names}")
            self._getters = [(n, make_getter(p)) for n, p in zip(self._names, self._paths, strict=True)]
        else:
            self._tree = _build_tree(self._paths)

    def process(self, sample: Sample, now_ns: int) -> list[Sample]:  # noqa: ARG002 - stateless
        """A new sample with only the chosen fields; a sample lacking one is counted as an error and
        dropped."""
        counters = self.counters
        counters.received += 1
        try:
            if self.flatten:
                value = {name: get(sample.value) for name, get in self._getters}
            else:
                value = _pick(self._tree, sample.value)
        except _SAMPLE_ERRORS as exc:
            counters.errors += 1
            self.last_error = f"{type(exc).__name__}: {exc}"
            return []
        counters.passed += 1
        counters.emitted += 1
        return [Sample(sample.robot, sample.topic, sample.stamp_ns, value, None)]

    def tick(self, now_ns: int) -> list[Sample]:  # noqa: ARG002 - nothing is time-driven here
        """Nothing: the stage holds no samples."""
        return []

    def derived_name(self, input_schema: dict[str, Any]) -> str:
        """The full name of the derived record: the input's name, ``_proj_`` and a hash of the options."""
        index, root = root_node(input_schema)
        full = index.fullname_of(root) or "record"
        return f"{full}_proj_{short_hash([list(self.fields), self.flatten])}"

    def output_schema(self, input_schema: dict[str, Any]) -> dict[str, Any]:
        """The derived record schema with only the chosen fields; raises ``StageConfigError`` when a path
        is not in the input."""
        index, root = root_node(input_schema)
        full = self.derived_name(input_schema)
        defined: set[str] = set()
        doc = f"Projection of {index.fullname_of(root)} onto {', '.join(self.fields)}"
        if self.flatten:
            fields = []
            for name, steps in zip(self._names, self._paths, strict=True):
                node, extra = _declared(index, root, steps)
                fields.append({"name": name, "type": copy_self_contained(node, index, defined), **extra})
            return {"type": "record", "name": full, "doc": doc, "fields": fields}
        for steps in self._paths:
            resolve_path(index, root, steps)
        record = self._nested_record(index, root, self._tree, (), full, defined=defined)
        record["doc"] = doc
        return record

    def _nested_record(
        self, index: SchemaIndex, root: Node, tree: Tree, prefix: Steps, full: str, *, defined: set[str]
    ) -> dict[str, Any]:
        fields = []
        for name, sub in tree:
            steps = (*prefix, name)
            node, extra = _declared(index, root, steps)
            if sub is None:
                field_type = copy_self_contained(node, index, defined)
            else:
                field_type = self._nested_record(index, root, sub, steps, f"{full}_{name}", defined=defined)
                extra = {k: v for k, v in extra.items() if k == "doc"}  # a pruned record is no ROS type
            fields.append({"name": name, "type": field_type, **extra})
        return {"type": "record", "name": full, "fields": fields}
