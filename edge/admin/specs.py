"""A config's declarations as mapping-table specs, keeping unchanged stage lists identical.

The runtime rebuilds a mapping's stages (and loses their state: open aggregate windows, throttle
timers) when the stage tuple it sees is a different object. ``declarations`` reuses the live
table's tuple for every mapping whose stages did not change, so changing one mapping leaves
the others' state alone.
"""

from __future__ import annotations

import dataclasses

from fleetlink.edge.config import EdgeConfig, MappingConfig
from fleetlink.edge.mapping import MappingSpec, MappingTable, RobotTypeSpec


def declarations(
    config: EdgeConfig, live: MappingTable | None = None
) -> tuple[list[RobotTypeSpec], list[MappingSpec]]:
    """Robot types and site-level mappings of ``config``, ready for ``MappingTable.reload``."""
    stages = {(info.name, info.robot_type): info.stages for info in live.list()} if live is not None else {}

    def spec(mapping: MappingConfig, owner: str | None) -> MappingSpec:
        fresh = mapping.spec()
        kept = stages.get((mapping.name, owner))
        if kept is not None and kept == fresh.stages:
            return dataclasses.replace(fresh, stages=kept)
        return fresh

    types = [
        RobotTypeSpec(name=name, match=rt.match, mappings=tuple(spec(m, name) for m in rt.mappings))
        for name, rt in config.robot_types.items()
    ]
    return types, [spec(m, None) for m in config.mappings]
