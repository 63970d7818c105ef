"""``auction``: the Consensus-Based Bundle Algorithm (CBBA; Choi, Brunet & How, IEEE T-RO 2009).

Parameters (``[dispatch.allocator_params]``)
    ``bundle_size`` (int, default 1): the most tasks an agent bids for at once, ``L``. ``L = 1``
    is CBAA, the paper's one-task-per-agent setting. ``time_scale`` (seconds, default 60): the
    discount of the time-discounted reward used when ``L > 1`` (see Scores).

The algorithm, per agent ``i``, in synchronous iterations (one iteration = one round):

1. **Bundle construction.** While its bundle ``b_i`` has fewer than ``L`` tasks, the agent
   computes for every task ``j`` it can serve the *marginal score* ``c_ij`` of inserting ``j``
   at the best position of its path ``p_i``, and takes the task with the highest ``c_ij`` among
   those where ``c_ij`` beats the winning bid it knows, ``y_ij`` (ties to the lower agent
   index); it records ``y_ij = c_ij``, ``z_ij = i``.
2. **Consensus.** Every agent broadcasts ``(y_i, z_i, s_i)`` (winning bids, winners, and the
   time it last heard, directly or indirectly, from each agent) to its neighbours in the
   communication graph. Each receiver applies the update / reset / leave rules of the paper's
   Table 1 task by task, then drops from its bundle the first task it was outbid on and every
   task added after it (their bids assumed the dropped task; its own bids on them are
   withdrawn, what it heard of other agents' bids on them is kept).

Iterations repeat until a fixed point: no winning bid or winner changes and the agents of every
connected component agree on ``(y, z)`` (checked by the simulator, which sees all agents: under
message loss "nothing changed this round" alone is not proof). On a connected graph the result
is conflict-free. The limit is ``problem.max_rounds``.

Scores
    ``L = 1``: the bid of agent ``i`` on task ``j`` is ``-cost[i, j]``, so the auction ranks
    pairs by cost (any decreasing function of cost gives the same assignment).
    ``L > 1``: a path's score is the time-discounted reward ``sum_k exp(-tau_k / time_scale)``
    over its tasks, ``tau_k`` the arrival time at the k-th task: the first leg is the exact
    ``cost`` (the planner's travel time), later legs are straight-line distance / speed (the
    problem has no task-to-task travel times; a lower bound), and no arrival is earlier than
    the task's own ``cost`` (nothing beats the shortest path from the start). The marginal score
    of a task is the score of the path with the task at its best position minus the score of the
    path without it. Bids are *warped* (Johnson, Ponda, Choi & How 2012): an agent
    never bids more than its previous bid in the bundle, which keeps the diminishing marginal
    gain that CBBA's convergence needs whatever the cost matrix.

Hand-out and conflicts
    The simulator serves one task per vehicle at a time, so each agent *claims* only the first
    task of its path (the first it would visit); the rest of its bundle stays open and is
    allocated again when vehicles become idle. Claims go to the tasks' arbiters in one round of
    the shared decision rounds (:func:`dispatch.api.decentralized.run_rounds`): on a connected graph
    at convergence they never collide; on a disconnected graph (or when ``max_rounds`` stopped
    consensus) colliding claims are settled by the conflict rule, reported as conflicts in the
    request log, and the losers go on requesting tasks they still believe open (cheapest first)
    in further rounds.

Counting
    ``rounds`` = consensus iterations + rounds of claims and requests. ``messages`` = consensus
    broadcasts (one per agent with a neighbour per iteration) + claims, requests and relays.
    ``hops`` = one per consensus iteration + two per claim/request round (request, answer).
    ``agent_seconds``: each agent's share of the vectorized computation of each step.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numpy as np

from allocators import _cbba_fast
from dispatch.api.comms import Channel, components
from dispatch.api.contracts import Allocator
from dispatch.api.decentralized import run_rounds
from dispatch.api.problem import Allocation, AllocationProblem

NONE = -1
_BIG = np.iinfo(np.int64).max


def better(ya, za, yb, zb):
    """Bid ``(ya, by agent za)`` beats bid ``(yb, by zb)``: higher value, ties to the lower agent
    index (no winner, ``-1``, counts as the highest index). Works elementwise."""
    za = np.where(np.asarray(za) < 0, _BIG, za)
    zb = np.where(np.asarray(zb) < 0, _BIG, zb)
    return (ya > yb) | ((ya == yb) & (za < zb))


@dataclass
class CBBAResult:
    """The state at the end of consensus (indices, not ids)."""

    y: np.ndarray  # (N, M) winning bids each agent knows (-inf: none)
    z: np.ndarray  # (N, M) winners each agent knows (-1: none)
    bundles: list[list[int]]  # tasks in the order they were added
    paths: list[list[int]]  # the same tasks in visiting order
    rounds: int
    messages: int
    converged: bool
    seconds: np.ndarray  # (N,) compute seconds per agent

    def claims(self) -> np.ndarray:
        """Each agent's first task to visit, or -1."""
        return np.array([p[0] if p else NONE for p in self.paths], dtype=np.int64)

    def conflicts(self) -> set[int]:
        """Task indices claimed by more than one agent."""
        c = self.claims()
        c = c[c >= 0]
        u, k = np.unique(c, return_counts=True)
        return set(u[k > 1].tolist())


class AuctionAllocator(Allocator):
    """CBBA auction over the communication graph (bundle_size=1: CBAA); see the module doc."""

    name = "auction"
    decentralized = True

    def __init__(self, bundle_size: int = 1, time_scale: float = 60.0) -> None:
        if isinstance(bundle_size, bool) or not isinstance(bundle_size, int) or bundle_size < 1:
            raise TypeError(f"bundle_size must be an integer >= 1, got {bundle_size!r}")
        if (isinstance(time_scale, bool) or not isinstance(time_scale, (int, float))
                or not math.isfinite(time_scale) or time_scale <= 0):
            raise TypeError(f"time_scale must be a number > 0 (seconds), got {time_scale!r}")
        self.bundle_size = bundle_size
        self.time_scale = float(time_scale)
        self.last: CBBAResult | None = None  # the last consensus, for inspection

    # ------------------------------------------------------------------ the allocator
    def allocate(self, problem: AllocationProblem) -> Allocation:
        n, m = problem.cost.shape
        res = self.consensus(problem)
        self.last = res
        if n == 0 or m == 0:
            return Allocation(pairs=(), rounds=res.rounds, messages=res.messages,
                              hops=res.rounds, agent_seconds=tuple(res.seconds.tolist()))
        known = (res.z >= 0) & (res.z != np.arange(n)[:, None])  # taken by someone else
        claims = res.claims()
        # An agent with nothing in its bundle (possible only if consensus was cut short) asks
        # for the cheapest task it believes open, as in the later rounds.
        empty = claims < 0
        if empty.any():
            claims[empty] = _cheapest(problem, np.flatnonzero(empty), ~known[empty])
        settle = run_rounds(problem, _cheapest_choose, first=claims, known=known,
                            start_round=res.rounds)
        seconds = res.seconds + np.asarray(settle.agent_seconds, dtype=float)
        return Allocation(pairs=settle.pairs, rounds=res.rounds + settle.rounds,
                          requests=settle.requests, messages=res.messages + settle.messages,
                          hops=res.rounds + settle.hops,
                          agent_seconds=tuple(float(x) for x in seconds))

    # ------------------------------------------------------------------ CBBA
    def consensus(self, problem: AllocationProblem) -> CBBAResult:
        """Run CBBA's two phases to a fixed point (or ``problem.max_rounds``)."""
        return _CBBA(problem, self.bundle_size, self.time_scale).run()

    # scores, exposed for tests and analysis
    def path_score(self, problem: AllocationProblem, agent: int, path: list[int]) -> float:
        """The score of visiting ``path`` (task indices) in order (see the module doc)."""
        return _CBBA(problem, self.bundle_size, self.time_scale).path_score(agent, path)


def _cheapest(problem: AllocationProblem, agents: np.ndarray, open_rows: np.ndarray) -> np.ndarray:
    costs = np.where(open_rows, problem.cost[agents], np.inf)
    best = np.argmin(costs, axis=1) if costs.shape[1] else np.zeros(len(agents), np.int64)
    return np.where(np.isfinite(costs).any(axis=1), best, NONE)


def _cheapest_choose(problem, agents, open_tasks, round_):
    return _cheapest(problem, agents, np.broadcast_to(open_tasks, (len(agents), len(open_tasks))))


class _CBBA:
    """The state of one CBBA run (all agents, simulated side by side)."""

    def __init__(self, problem: AllocationProblem, bundle_size: int, time_scale: float) -> None:
        self.p = problem
        n, m = problem.cost.shape
        self.n, self.m, self.L, self.T = n, m, bundle_size, time_scale
        self.cost = np.asarray(problem.cost, dtype=float)
        self.feasible = np.isfinite(self.cost)
        self.y = np.full((n, m), -np.inf)
        self.z = np.full((n, m), NONE, dtype=np.int64)
        self.s = np.zeros((0, 0), dtype=np.int64)  # made by run() (N x N; not for one task)
        self.bundles: list[list[int]] = [[] for _ in range(n)]
        self.paths: list[list[int]] = [[] for _ in range(n)]
        self.seconds = np.zeros(n)
        if bundle_size > 1:  # (also with no task: marginals() reads speed)
            pos = problem.task_pos
            # metres between tasks (straight line)
            self.legs = np.linalg.norm(pos[:, None] - pos[None, :], axis=-1)
            self.speed = np.array([a.speed for a in problem.agents], dtype=float)

    # -------------------------------------------------------------- scores (L > 1)
    def arrivals(self, i: int, path: list[int]) -> np.ndarray:
        """Arrival times along ``path``: ``tau_1 = cost[i, p_1]``, then
        ``tau_q = max(tau_{q-1} + leg / speed, cost[i, p_q])`` (no route through other tasks
        beats the planner's shortest path from the start)."""
        tau = np.empty(len(path))
        t = 0.0
        for q, j in enumerate(path):
            t = self.cost[i, j] if q == 0 else max(t + self.legs[path[q - 1], j] / self.speed[i],
                                                   self.cost[i, j])
            tau[q] = t
        return tau

    def path_score(self, i: int, path: list[int]) -> float:
        if self.L == 1:
            return float(-sum(self.cost[i, j] for j in path))
        return float(np.exp(-self.arrivals(i, path) / self.T).sum())

    def marginals(self, i: int) -> tuple[np.ndarray, np.ndarray]:
        """Best marginal score ``S(path with j inserted) - S(path)`` of each task, and where."""
        path, T = self.paths[i], self.T
        cost_i = self.cost[i]
        if self.L == 1:  # the bundle is empty whenever this is asked
            return -cost_i, np.zeros(self.m, dtype=np.int64)
        tau = self.arrivals(i, path)
        base = np.exp(-tau / T)
        v = self.speed[i]
        best = np.full(self.m, -np.inf)
        where = np.zeros(self.m, dtype=np.int64)
        k = len(path)
        with np.errstate(invalid="ignore"):  # inf costs of tasks the agent cannot serve
            for q in range(k + 1):  # insert j before path[q] (q = k: at the end)
                tj = cost_i if q == 0 else np.maximum(tau[q - 1] + self.legs[path[q - 1]] / v,
                                                      cost_i)
                gain = np.exp(-tj / T) - base[q:].sum()
                t, prev = tj, None
                for r in range(q, k):  # the tasks after j, each chain vectorized over j
                    nxt = path[r]
                    leg = self.legs[:, nxt] if prev is None else self.legs[prev, nxt]
                    t = np.maximum(t + leg / v, cost_i[nxt])
                    gain = gain + np.exp(-t / T)
                    prev = nxt
                take = gain > best
                best = np.where(take, gain, best)
                where = np.where(take, q, where)
        best = np.where(self.feasible[i], best, -np.inf)
        return best, where

    # -------------------------------------------------------------- phase 1
    def build_bundles(self) -> bool:
        """Bundle construction for every agent; True if any bid was placed."""
        changed = False
        if self.L == 1:
            t0 = time.perf_counter()
            free = np.array([not b for b in self.bundles], dtype=bool)
            idx = np.flatnonzero(free)
            if idx.size == 0 or self.m == 0:
                return False
            bids = np.where(self.feasible[idx], -self.cost[idx], -np.inf)
            h = self.feasible[idx] & better(bids, idx[:, None], self.y[idx], self.z[idx])
            pick = np.argmax(np.where(h, bids, -np.inf), axis=1)
            bidding = h.any(axis=1)
            rows, who = np.flatnonzero(bidding), idx[bidding]
            js = pick[rows]
            for i, j in zip(who.tolist(), js.tolist()):
                self.bundles[i] = [j]
                self.paths[i] = [j]
            self.y[who, js], self.z[who, js] = bids[rows, js], who
            changed = bool(rows.size)
            self.seconds[idx] += (time.perf_counter() - t0) / idx.size
            return changed
        for i in range(self.n):
            t0 = time.perf_counter()
            while len(self.bundles[i]) < self.L:
                c, where = self.marginals(i)
                if self.bundles[i]:
                    last = self.y[i, self.bundles[i][-1]]
                    w = np.minimum(c, last)
                else:
                    w = c
                h = self.feasible[i] & (w > -np.inf) & better(w, i, self.y[i], self.z[i])
                h[self.bundles[i]] = False
                if not h.any():
                    break
                cand = np.flatnonzero(h)
                # highest warped bid, then highest raw marginal, then lowest task index
                order = np.lexsort((cand, -c[cand], -w[cand]))
                j = int(cand[order[0]])
                self.paths[i].insert(int(where[j]), j)
                self.bundles[i].append(j)
                self.y[i, j], self.z[i, j] = w[j], i
                changed = True
            self.seconds[i] += time.perf_counter() - t0
        return changed

    # -------------------------------------------------------------- phase 2
    def exchange(self, got: np.ndarray, now: int) -> None:
        """Every receiver applies the broadcasts it got (``got[k, i]``), sender by sender
        (compiled: :func:`allocators._cbba_fast.exchange`, the rules of :meth:`_apply`)."""
        t0 = time.perf_counter()
        y0, z0, s0 = self.y.copy(), self.z.copy(), self.s.copy()  # what was sent
        work = _cbba_fast.exchange(self.y, self.z, self.s, np.ascontiguousarray(got, bool),
                                   y0, z0, s0, now)
        total = work.sum()
        if total:  # each agent's share of the time, by the broadcasts it processed
            self.seconds += (time.perf_counter() - t0) * work / total

    def exchange_reference(self, got: np.ndarray, now: int) -> None:
        """:meth:`exchange` in numpy, sender by sender (the reference the tests compare with)."""
        y0, z0, s0 = self.y.copy(), self.z.copy(), self.s.copy()  # what was sent
        for k in range(self.n):
            rec = np.flatnonzero(got[k])
            if rec.size == 0:
                continue
            t0 = time.perf_counter()
            self._apply(k, rec, y0[k], z0[k], s0[k])
            self.s[rec, k] = now
            self.s[rec] = np.maximum(self.s[rec], s0[k][None, :])
            self.s[rec, rec] = now
            self.seconds[rec] += (time.perf_counter() - t0) / rec.size

    def _apply(self, k: int, rec: np.ndarray, yk, zk, sk) -> None:
        """CBBA's Table 1: receiver i (rows ``rec``) and sender k, for every task at once.

        Only tasks where some receiver's ``(y, z)`` differs from the sender's are looked at:
        where they agree, every rule leaves the entry as it is."""
        Y, Z = self.y[rec], self.z[rec]
        cols = np.flatnonzero(((Z != zk[None, :]) | (Y != yk[None, :])).any(axis=0))
        if cols.size == 0:
            return
        if cols.size < self.m:
            yk, zk = yk[cols], zk[cols]
            Y, Z = Y[:, cols], Z[:, cols]
        S = self.s[rec]
        i = rec[:, None]
        zk_b = np.broadcast_to(zk, Z.shape)
        s_km = np.where(zk >= 0, sk[np.maximum(zk, 0)], -1)[None, :]  # k's time for k's winner
        s_im = np.where(zk_b >= 0, np.take_along_axis(S, np.maximum(zk_b, 0), axis=1), -1)
        s_kn = np.where(Z >= 0, sk[np.maximum(Z, 0)], -1)  # k's time for i's winner
        s_in = np.where(Z >= 0, np.take_along_axis(S, np.maximum(Z, 0), axis=1), -1)
        beats = better(yk[None, :], zk_b, Y, Z)

        k_is_k = zk_b == k
        k_is_i = zk_b == i
        k_none = zk_b == NONE
        k_m = ~(k_is_k | k_is_i | k_none)
        i_is_i = Z == i
        i_is_k = Z == k
        i_none = Z == NONE
        i_other = ~(i_is_i | i_is_k | i_none)
        i_same = i_other & (Z == zk_b)
        i_n = i_other & ~i_same
        newer_m = s_km > s_im
        newer_n = s_kn > s_in
        older_m = s_im > s_km

        update = (
            (k_is_k & ((i_is_i & beats) | i_is_k | (i_other & (newer_n | beats)) | i_none))
            | (k_m & ((i_is_i & newer_m & beats) | (i_is_k & newer_m) | (i_same & newer_m)
                      | (i_n & newer_m & (newer_n | beats)) | (i_none & newer_m)))
            | (k_none & (i_is_k | (i_other & newer_n)))
        )
        reset = (
            (k_is_i & (i_is_k | (i_other & newer_n)))
            | (k_m & ((i_is_k & ~newer_m) | (i_n & newer_n & older_m)))
        )
        Y = np.where(update, yk[None, :], np.where(reset, -np.inf, Y))
        Z = np.where(update, zk_b, np.where(reset, NONE, Z))
        if cols.size < self.m:
            self.y[np.ix_(rec, cols)], self.z[np.ix_(rec, cols)] = Y, Z
        else:
            self.y[rec], self.z[rec] = Y, Z

    def release_outbid(self) -> bool:
        """Drop from each bundle the first task the agent lost and every task after it."""
        changed = False
        if self.L == 1:  # one task per bundle: drop it where the agent is no longer its winner
            held = np.array([b[0] if b else NONE for b in self.bundles], dtype=np.int64)
            agents = np.flatnonzero(held >= 0)
            lost = agents[self.z[agents, held[agents]] != agents]
            for i in lost.tolist():
                self.bundles[i], self.paths[i] = [], []
            return bool(lost.size)
        for i in range(self.n):
            b = self.bundles[i]
            if not b:
                continue
            lost = [q for q, j in enumerate(b) if self.z[i, j] != i]
            if not lost:
                continue
            cut = lost[0]
            for j in b[cut + 1:]:
                if self.z[i, j] == i:  # withdraw own bids that assumed the dropped task
                    self.y[i, j], self.z[i, j] = -np.inf, NONE
            dropped = set(b[cut:])
            self.bundles[i] = b[:cut]
            self.paths[i] = [j for j in self.paths[i] if j not in dropped]
            changed = True
        return changed

    def agreed(self, labels: np.ndarray) -> bool:
        """Every connected component agrees on winners and winning bids."""
        for c in np.unique(labels):
            members = np.flatnonzero(labels == c)
            if members.size < 2:
                continue
            y, z = self.y[members], self.z[members]
            if not ((z == z[0]).all() and (y == y[0]).all()):
                return False
        return True

    def one_task(self) -> CBBAResult | None:
        """CBAA's result for one task on a complete graph without loss, without simulating it
        (immediate dispatch: a request at a time to a fleet of idle taxis), or None where
        that does not apply. Round 0: every agent that can serve the task bids; every agent
        hears every bid and keeps the best (highest bid, ties to the lower index: the
        cheapest agent); round 1 changes nothing and they agree. The same state, rounds and
        messages as :meth:`run` (the tests compare)."""
        p = self.p
        if self.L != 1 or self.m != 1 or p.loss > 0 or self.n == 0 or not np.all(p.comm):
            return None
        t0 = time.perf_counter()
        feasible = self.feasible[:, 0]
        if not feasible.any():  # nobody bids; everyone agrees on nothing at once
            return CBBAResult(y=self.y, z=self.z, bundles=self.bundles, paths=self.paths,
                              rounds=0, messages=0, converged=True, seconds=self.seconds)
        best = int(np.argmin(np.where(feasible, self.cost[:, 0], np.inf)))
        self.y[:, 0], self.z[:, 0] = -self.cost[best, 0], best
        self.bundles[best], self.paths[best] = [0], [0]
        self.seconds += (time.perf_counter() - t0) / self.n
        return CBBAResult(y=self.y, z=self.z, bundles=self.bundles, paths=self.paths,
                          rounds=1, messages=self.n if self.n > 1 else 0, converged=True,
                          seconds=self.seconds)

    def run(self) -> CBBAResult:
        p = self.p
        shortcut = self.one_task()
        if shortcut is not None:
            return shortcut
        self.s = np.full((self.n, self.n), -1, dtype=np.int64)
        channel = Channel(p.comm, p.loss, p.rng)
        _, labels = components(p.comm)
        everyone = np.arange(self.n)
        rounds, converged = 0, False
        for r in range(p.max_rounds):
            self.s[everyone, everyone] = r
            changed = self.build_bundles()
            if not changed and self.agreed(labels):
                converged = True
                break
            got = channel.broadcast_all(everyone)
            self.exchange(got, r)
            t0 = time.perf_counter()
            self.release_outbid()
            if self.n:
                self.seconds += (time.perf_counter() - t0) / self.n
            rounds = r + 1
        else:
            converged = self.n == 0 or self.m == 0
        return CBBAResult(y=self.y, z=self.z, bundles=self.bundles, paths=self.paths,
                          rounds=rounds, messages=channel.transmissions, converged=converged,
                          seconds=self.seconds)
