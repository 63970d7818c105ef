"""The ``dijkstra`` planner: exact travel times and fastest paths on a road network.

Promises
    * ``costs`` is exact: ``cost[a, t]`` is the fastest driving time in seconds from
      ``agents[a].loc`` to the node ``tasks[t].loc`` under the network's edge times:
      ``loc.remaining`` plus the shortest time from ``loc.node`` for a vehicle part-way along an
      edge (it finishes the edge first), the shortest time from the node for an ``int``.
      The network's times are the vehicles' times (``agent.speed`` is not used: a road's time
      already says how fast it is driven). ``inf`` only where no path exists (never inside one
      network from :mod:`dispatch.roads`, which keeps a strongly connected component).
    * A task's column comes from the field "seconds from every node to the task's node"
      (:meth:`~dispatch.roads.RoadNetwork.distances_to`: Dijkstra on the transposed graph),
      computed the first time a decision needs it and kept until :meth:`RoadPlanner.task_closed`;
      tasks on one node share one field. A later decision only gathers at the agents' nodes.
    * When a decision has many more uncached task nodes than distinct agent nodes
      (``FORWARD_RATIO`` times as many), one forward Dijkstra per agent node answers those
      tasks instead (same numbers, nothing cached): e.g. 5 taxis and 500 fresh requests cost 5
      searches, not 500.
    * ``plan`` returns a fastest node path (scipy Dijkstra with predecessors) whose time equals
      the cost, or None.

Statistics: ``stats.cost_queries``, ``stats.plans``; ``stats.extra`` holds ``fields_computed``
(backward searches), ``field_reuses`` (task columns read from the cache) and
``forward_searches``.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from dispatch.contracts import Planner
from dispatch.roads import RoadNetwork, RoadPoint

#: Forward searches (one per distinct agent node, nothing cached) replace backward fields when
#: the uncached task nodes outnumber the agent nodes by at least this factor. One search costs
#: the same either way (1.2-1.3 ms on Chicago, each direction); a field is reused at every later
#: decision the task stays open, so fields win unless the uncached side is clearly larger.
FORWARD_RATIO = 4


class RoadPlanner(Planner):
    """Exact road planner: cached Dijkstra fields per task node, fastest paths by Dijkstra."""

    name = "dijkstra"
    spaces = ("road",)

    def __init__(self, space: RoadNetwork) -> None:
        if not isinstance(space, RoadNetwork):
            raise TypeError(f"planner {self.name!r} serves road networks, not "
                            f"{type(space).__name__} (space kind {getattr(space, 'kind', None)!r})")
        super().__init__(space)
        self.space = space
        self._node_of: dict[Any, int] = {}  # task id -> its node
        self._fields: dict[int, np.ndarray] = {}  # node -> seconds from every node to it
        self._users: dict[int, int] = {}  # node -> number of cached tasks on it
        self.stats.extra.setdefault("fields_computed", 0)
        self.stats.extra.setdefault("field_reuses", 0)
        self.stats.extra.setdefault("forward_searches", 0)

    def _remember(self, task_id: Any, node: int) -> None:
        old = self._node_of.get(task_id)
        if old == node:
            return
        if old is not None:
            self.task_closed(task_id)
        self._node_of[task_id] = node
        self._users[node] = self._users.get(node, 0) + 1

    def costs(self, agents: Sequence[Any], tasks: Sequence[Any]) -> np.ndarray:
        """Return the ``(len(agents), len(tasks))`` array of exact travel seconds (see module)."""
        self.stats.cost_queries += 1
        out = np.full((len(agents), len(tasks)), np.inf)
        if not agents or not tasks:
            return out
        node, rem = _agent_arrays([a.loc for a in agents])
        tnode = np.fromiter((int(t.loc) for t in tasks), np.int64, len(tasks))
        cached = np.fromiter((int(n) in self._fields for n in tnode), bool, len(tasks))
        fresh = np.unique(tnode[~cached])
        agent_nodes, agent_inv = np.unique(node, return_inverse=True)

        reused = int(cached.sum())
        if fresh.size >= FORWARD_RATIO * agent_nodes.size:
            # a few agents, many new tasks: search forward from the agents, cache nothing
            self.stats.extra["forward_searches"] += int(agent_nodes.size)
            fwd = self.space.distances_from(agent_nodes)
            cols = np.flatnonzero(~cached)
            out[:, cols] = fwd[np.ix_(agent_inv, tnode[cols])]
        elif fresh.size:
            for n, field in zip(fresh.tolist(), self.space.distances_to(fresh)):
                field = field.copy()  # own row: a dropped field must not pin its whole block
                field.setflags(write=False)
                self._fields[n] = field
            self.stats.extra["fields_computed"] += int(fresh.size)
            cached[:] = True
        self.stats.extra["field_reuses"] += reused

        hits = np.flatnonzero(cached).tolist()
        for t in hits:
            out[:, t] = self._fields[int(tnode[t])][node]
        for t in hits:  # after reading: re-homing a task may drop a field
            self._remember(tasks[t].id, int(tnode[t]))
        return out + rem[:, None]

    def plan(self, agent: Any, goal: int) -> list[int] | None:
        """A fastest node path from the agent's node (``agent.loc.node``, or ``agent.loc``) to
        ``goal``, both included (``[goal]`` when already there), or None if unreachable."""
        self.stats.plans += 1
        leg = self.space.route(agent.loc, int(goal))
        return None if leg is None else leg.nodes.tolist()

    def task_closed(self, task_id: Any) -> None:
        """Forget the task; its node's field goes once no other cached task stands on it."""
        node = self._node_of.pop(task_id, None)
        if node is None:
            return
        left = self._users.get(node, 1) - 1
        if left > 0:
            self._users[node] = left
        else:
            self._users.pop(node, None)
            self._fields.pop(node, None)


def _agent_arrays(locs: Sequence[RoadPoint | int]) -> tuple[np.ndarray, np.ndarray]:
    """``(node, remaining seconds)`` of agent locations (points or node ints)."""
    node = np.empty(len(locs), dtype=np.int64)
    rem = np.zeros(len(locs))
    for i, loc in enumerate(locs):
        if isinstance(loc, RoadPoint):
            node[i], rem[i] = loc.node, max(loc.remaining, 0.0)
        else:
            node[i] = int(loc)
    return node, rem
