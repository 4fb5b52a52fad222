"""``TableBackend``: an ``AdminBackend`` over a ``MappingTable`` and a graph source.

What an edge needs besides its table comes in as callables (robot states, counters, what to do
after a change), so the same class serves the agent and tests that run a table on a real
router without the rest of the agent. With ``register_robots`` it also registers, after each
change, the robots of the graph that a (new) robot type's ``match`` takes.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from typing import Any, Protocol

from fleetlink.edge.admin.backend import EdgeSnapshot, RobotStatus
from fleetlink.edge.config import EdgeConfig
from fleetlink.edge.errors import MappingError
from fleetlink.edge.mapping import MappingSpec, MappingTable, RobotTypeSpec
from fleetlink.roswire.graph import TopicInfo


class GraphSource(Protocol):
    """Where a ``TableBackend`` finds the discovered ROS topics (a ``GraphWatcher``)."""

    def topics(self) -> dict[str, TopicInfo]:
        """The discovered ROS topics by name."""
        ...


class TableBackend:
    """An ``AdminBackend`` over a ``MappingTable`` and a graph source; counters, robot states and spool
    damage come from the callables given (neutral defaults without them)."""

    def __init__(
        self,
        table: MappingTable,
        graph: GraphSource,
        *,
        snapshot: Callable[[], EdgeSnapshot] | None = None,
        robots: Callable[[], Sequence[RobotStatus]] | None = None,
        on_install: Callable[[EdgeConfig], object] | None = None,
        register_robots: bool = False,
        spool_damage: Callable[[], Sequence[Mapping[str, Any]]] | None = None,
        acknowledge_spool_damage: Callable[[], Sequence[Mapping[str, Any]]] | None = None,
    ) -> None:
        self.table = table
        self.graph = graph
        self._snapshot = snapshot or EdgeSnapshot
        self._robots = robots
        self._on_install = on_install
        self.register_robots = register_robots
        self._damage = spool_damage or tuple
        self._acknowledge = acknowledge_spool_damage or tuple
        self.installs = 0

    def install(
        self, config: EdgeConfig, robot_types: Sequence[RobotTypeSpec], mappings: Sequence[MappingSpec]
    ) -> None:
        """Reload the table with the new declarations, register matching robots when ``register_robots`` is
        set, then call ``on_install``."""
        self.table.reload(robot_types, mappings)
        if self.register_robots:
            self.discover()
        self.installs += 1
        if self._on_install is not None:
            self._on_install(config)

    def discover(self) -> list[str]:
        """Register every robot namespace of the graph that a robot type matches; returns them."""
        known = self.table.robots()
        added = []
        for topic in sorted(self.graph.topics()):
            robot = topic.strip("/").split("/")[0]
            if not robot or robot in known or self.table.robot_type_for(robot) is None:
                continue
            try:
                self.table.add_robot(robot)
            except MappingError:
                continue
            known[robot] = ""
            added.append(robot)
        return added

    def mapping_table(self) -> MappingTable:
        """The live mapping table."""
        return self.table

    def topics(self) -> Mapping[str, TopicInfo]:
        """The graph source's discovered topics."""
        return self.graph.topics()

    def robots(self) -> Sequence[RobotStatus]:
        """The robots from the ``robots`` callable, or else the table's robots as registered."""
        if self._robots is not None:
            return self._robots()
        return [RobotStatus(robot=r, robot_type=t) for r, t in sorted(self.table.robots().items())]

    def snapshot(self) -> EdgeSnapshot:
        """The edge's state from the ``snapshot`` callable (an empty snapshot without one)."""
        return self._snapshot()

    def spool_damage(self) -> Sequence[Mapping[str, Any]]:
        """The spool damage findings from the ``spool_damage`` callable (none without one)."""
        return self._damage()

    def acknowledge_spool_damage(self) -> Sequence[Mapping[str, Any]]:
        """Acknowledge through the ``acknowledge_spool_damage`` callable; returns the findings that were
        waiting."""
        return self._acknowledge()
