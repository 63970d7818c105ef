"""The communication model: who can talk to whom at a decision, and what a message costs.

Scenario section ``[comms]`` (all optional)::

    range = 20.0     # metres; omitted: unlimited (every idle agent hears every other)
    latency = 0.05   # simulated seconds per message hop (default 0)
    loss = 0.1       # probability that one reception of a message is lost (default 0)

Graph
    At each decision :class:`Hearing` builds the graph over the *idle* agents of that decision
    (the agents of the :class:`~dispatch.api.problem.AllocationProblem`) from the centres of their
    cells: two agents are linked when their straight-line distance is at most ``range``.
    Obstacles do not block radio, and busy vehicles do not relay (they are not part of the
    decision). The adjacency is symmetric and its diagonal is True (an agent always "hears"
    itself); :func:`neighbours` gives the off-diagonal part.

Messages
    A message is one *broadcast*: one transmission, heard by every neighbour of the sender. With
    ``loss > 0`` each reception is dropped independently with that probability, drawn from the
    decision's generator (``problem.rng``; nothing is drawn when ``loss == 0``, so runs without
    loss draw exactly what they drew before the model existed). ``messages`` in results counts
    transmissions, not receptions; an agent without neighbours sends nothing.

Latency
    Decentralized allocators run in synchronous rounds; a round is as slow as its slowest hop.
    An allocator reports the number of sequential hops of its decision
    (:attr:`~dispatch.api.problem.Allocation.hops`); the dispatcher holds the hand-out back by
    ``hops * latency`` simulated seconds (see :mod:`dispatch.decide.dispatcher`). Centralized
    methods
    report 0 hops.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from scipy.sparse import csr_matrix

from dispatch.api.problem import AgentViews


def comm_graph(positions, comm_range: float | None) -> np.ndarray:
    """Symmetric boolean ``(N, N)`` adjacency of agents at ``positions`` (metres, ``(N, 3)``).

    ``None`` or ``inf`` range: everyone is linked. Distances equal to the range are linked.
    The diagonal is always True.
    """
    pos = np.asarray(positions, dtype=float).reshape(-1, 3)
    n = len(pos)
    if comm_range is None or math.isinf(comm_range):
        return np.ones((n, n), dtype=bool)
    if comm_range < 0 or math.isnan(comm_range):
        raise ValueError(f"communication range must be >= 0, got {comm_range!r}")
    adj = np.zeros((n, n), dtype=bool)
    if n > 1:
        # candidate pairs from a k-d tree (a fleet of 1,000 vehicles: no N x N distances),
        # then the same test as a dense comparison would make, pair by pair (scipy.spatial
        # imported here: only a run with a communication range pays for it)
        from scipy.spatial import cKDTree

        pairs = cKDTree(pos).query_pairs(comm_range + 1e-6, output_type="ndarray")
        if len(pairs):
            a, b = pairs[:, 0], pairs[:, 1]
            ok = np.linalg.norm(pos[a] - pos[b], axis=-1) <= comm_range + 1e-9
            adj[a[ok], b[ok]] = adj[b[ok], a[ok]] = True
    np.fill_diagonal(adj, True)
    return adj


def neighbours(comm: np.ndarray) -> np.ndarray:
    """The adjacency without its diagonal (who hears a broadcast of whom)."""
    nb = np.array(comm, dtype=bool, copy=True)
    np.fill_diagonal(nb, False)
    return nb


def components(comm: np.ndarray) -> tuple[int, np.ndarray]:
    """Number of connected components and each agent's component label."""
    n = len(comm)
    if n == 0:
        return 0, np.zeros(0, dtype=np.int64)
    if comm.all():  # everyone hears everyone (unlimited range): skip a dense N x N graph
        return 1, np.zeros(n, dtype=np.int64)
    # (imported here: scipy's graph module costs a run that never asks 0.07 s)
    from scipy.sparse.csgraph import connected_components

    count, labels = connected_components(csr_matrix(np.asarray(comm, bool)), directed=False)
    return int(count), labels.astype(np.int64)


def hop_distances(comm: np.ndarray) -> np.ndarray:
    """Hops between every pair of agents (``-1`` where they are not connected)."""
    n = len(comm)
    if n == 0:
        return np.zeros((0, 0), dtype=np.int64)
    from scipy.sparse.csgraph import shortest_path

    d = shortest_path(csr_matrix(neighbours(comm).astype(float)), unweighted=True,
                      directed=False)
    return np.where(np.isfinite(d), d, -1).astype(np.int64)


def diameter(comm: np.ndarray) -> int:
    """The largest hop distance between two connected agents (0 for none or one agent)."""
    d = hop_distances(comm)
    return int(d.max()) if d.size else 0


def relay_needed(comm: np.ndarray) -> np.ndarray:
    """``need[a, b]``: ``b`` hears ``a``, and has a neighbour that ``a`` does not reach, so after
    hearing a broadcast of ``a`` it should pass the news on.

    This is the self-pruning rule of neighbour-knowledge flooding (each agent knows its
    neighbours' neighbours): on a complete graph nobody ever relays.
    """
    comm = np.asarray(comm, dtype=bool)
    if comm.all():  # a complete graph (unlimited range): skip the N x N x N product
        return np.zeros(comm.shape, dtype=bool)
    nb = neighbours(comm)
    reach = comm  # a's broadcast covers a's neighbours and a itself
    # need[a, b] = b hears a, and any_c nb[b, c] & ~reach[a, c]. float32 counts are exact
    # below 2^24 agents and go through BLAS (an int64 product does not: 25 ms at N = 500)
    return ((nb.astype(np.float32) @ (~reach).T.astype(np.float32)).T > 0) & nb



def _positions(space, agents: AgentViews) -> np.ndarray:
    """``(N, 3)`` positions of a decision's agents: from their node array where they carry
    one (road points part-way along an edge one by one), else view by view."""
    nodes = agents.nodes
    if nodes is None:
        return space.positions([a.loc for a in agents])
    out = space.positions(nodes)
    for k in agents.points.tolist():
        out[k] = space.positions([agents[k].loc])[0]
    return out


class Hearing:
    """Who hears whom at a decision: the graph over its agents from their positions in
    ``space``, the ``[comms]`` range and ``links`` (``links(comm, positions, now) -> comm``:
    communication faults, a blackout; or None)."""

    def __init__(self, space, comms, links=None) -> None:
        self.space, self.comms, self.links = space, comms, links
        self._everyone: dict[int, np.ndarray] = {}  # n -> read-only all-True (n, n), no memory

    def __call__(self, agents: AgentViews, now: float):
        """``(comm, positions)`` of a decision's agents: who hears whom (the ``[comms]`` range,
        a blackout's links) and their ``(N, 3)`` positions; with an unlimited range and no
        faults a broadcast all-True ``comm`` (no N x N matrix) and the positions as a function
        computed only if someone reads them (nothing moves within the decision)."""
        comms, space = self.comms, self.space
        unlimited = comms.range is None or math.isinf(comms.range)
        if unlimited and self.links is None:  # everyone hears everyone: no N x N matrix
            comm = self._everyone.get(len(agents))
            if comm is None:
                comm = self._everyone[len(agents)] = np.broadcast_to(np.True_, (len(agents),) * 2)
            nodes = agents.nodes
            if nodes is not None and not agents.points.size:
                def apos():  # node positions (fixed now), computed if someone reads them
                    return space.positions(nodes)
            else:  # read if someone asks, within the decision (nothing moves meanwhile)
                def apos():
                    return _positions(space, agents)
            return comm, apos
        apos = _positions(space, agents)
        comm = comm_graph(apos, comms.range)
        if self.links is not None:
            comm = self.links(comm, apos, now)
        return comm, apos


@dataclass
class Channel:
    """Broadcasts over a communication graph, with independent loss per reception.

    ``transmissions`` counts broadcasts sent; ``receptions`` counts those that arrived.
    """

    comm: np.ndarray
    loss: float
    rng: np.random.Generator
    transmissions: int = 0
    receptions: int = 0
    _nb: np.ndarray = field(init=False, repr=False)

    def __post_init__(self) -> None:
        self._nb = neighbours(self.comm)

    @property
    def nb(self) -> np.ndarray:
        return self._nb

    def has_neighbours(self) -> np.ndarray:
        return self._nb.any(axis=1)

    def broadcast(self, sender: int) -> np.ndarray:
        """Send one broadcast from ``sender``; return the indices of the agents that got it.

        An agent without neighbours sends nothing (and is not counted)."""
        to = np.flatnonzero(self._nb[sender])
        if to.size == 0:
            return to
        self.transmissions += 1
        if self.loss > 0:
            to = to[self.rng.random(to.size) >= self.loss]
        self.receptions += int(to.size)
        return to

    def deliver(self, senders: np.ndarray) -> np.ndarray:
        """Who receives one broadcast from each of ``senders`` (in order), without counting
        transmissions: boolean ``(N, N)`` matrix ``got[k, i]``, agent ``i`` received ``k``'s.
        Loss draws, when ``loss > 0``, are made sender by sender in the given order."""
        n = len(self._nb)
        got = np.zeros((n, n), dtype=bool)
        senders = np.asarray(senders, dtype=np.int64)
        if senders.size == 0:
            return got
        rows = self._nb[senders]
        if self.loss > 0:
            rows = rows & (self.rng.random(rows.shape) >= self.loss)
        self.receptions += int(rows.sum())
        got[senders] = rows
        return got

    def broadcast_all(self, senders: np.ndarray) -> np.ndarray:
        """One broadcast from each of ``senders`` that has a neighbour (counted as one
        transmission each); returns ``got`` as :meth:`deliver`."""
        senders = np.asarray(senders, dtype=np.int64)
        self.transmissions += int(self._nb[senders].any(axis=1).sum()) if senders.size else 0
        return self.deliver(senders)
