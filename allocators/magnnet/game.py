"""The game's state and observations, for one instance (numpy) and for many at once (torch).

:class:`Game` plays one instance with plain numpy loops; it is what the PettingZoo environment
wraps and what the tests read as the rules. :class:`BatchedGame` plays ``B`` instances of the
same size at once with tensors, for training. A test steps both side by side on fixed seeds.

Observations (see :func:`global_obs`): per agent ``[status, flies, x, y, z]`` (``status`` 1
while the agent decides; position divided by the world's size), the costs divided by
:data:`~allocators.magnnet.rules.COST_SCALE` and capped at
:data:`~allocators.magnnet.rules.COST_CAP` (the cap also where the pair is unavailable),
``available`` (open and feasible), per task ``[open, x, y, z]``, and the communication adjacency
(diagonal included).
"""

from __future__ import annotations

import numpy as np
import torch

from allocators.magnnet import rules


class Game:
    """One instance of the allocation game (see :mod:`allocators.magnnet.rules`)."""

    def __init__(self, cost, agent_pos, task_pos, flies, world_size, comm=None) -> None:
        self.cost = np.asarray(cost, dtype=np.float64)
        n, m = self.cost.shape
        self.n, self.m = n, m
        self.agent_pos = np.asarray(agent_pos, np.float32)
        self.task_pos = np.asarray(task_pos, np.float32)
        self.flies = np.asarray(flies, bool)
        self.world_size = np.asarray(world_size, np.float32)
        self.comm = np.ones((n, n), bool) if comm is None else np.asarray(comm, bool)
        self.feasible = np.isfinite(self.cost)
        fin = self.cost[self.feasible]
        self.c_mean = float(fin.mean()) if fin.size else 1.0
        self.opt_count, self.opt_total = rules.optimal(self.cost)
        self.max_rounds = rules.max_rounds_for(m)
        self.agent_task = np.full(n, -1, np.int64)
        self.taken = np.zeros(m, bool)
        self.round = 0
        self.done = False
        self.conflicted = np.zeros(m, bool)

    def deciding(self) -> np.ndarray:
        return (self.agent_task < 0) & (self.feasible & ~self.taken).any(axis=1)

    def available(self) -> np.ndarray:
        return self.feasible & ~self.taken[None, :] & (self.agent_task < 0)[:, None]

    def total(self) -> float:
        a = np.flatnonzero(self.agent_task >= 0)
        return float(self.cost[a, self.agent_task[a]].sum())

    def step(self, actions: np.ndarray):
        """Play one round. ``actions[i]`` in ``0..M``; entries of non-deciding agents and
        requests of unavailable tasks count as rejects.

        Returns ``(rewards (N,), team_reward, acted (N,), ended (N,), done, truncated)``:
        ``acted`` marks the agents that decided this round, ``ended`` those whose game ends now.
        """
        dec = self.deciding()
        avail = self.available()
        rewards = np.zeros(self.n)
        req = np.full(self.n, -1, np.int64)
        owner = rules.cheapest_contender(np.where(avail, self.cost, np.inf))
        for i in np.flatnonzero(dec):
            a = int(actions[i])
            if a > 0 and avail[i, a - 1]:
                req[i] = a - 1
            elif (owner == i).any():
                rewards[i] += rules.R_REJECT
        winners: dict[int, int] = {}
        count = np.zeros(self.m, np.int64)
        for i in np.flatnonzero(req >= 0):
            t = int(req[i])
            count[t] += 1
            b = winners.get(t)
            if b is None or (self.cost[i, t], i) < (self.cost[b, t], b):
                winners[t] = i
        for i in np.flatnonzero(req >= 0):
            t = int(req[i])
            if count[t] > 1:
                if not rules.CONFLICT_LOSERS_ONLY or winners[t] != i:
                    rewards[i] += rules.R_CONFLICT
                self.conflicted[t] = True
        for t, i in winners.items():
            self.agent_task[i] = t
            self.taken[t] = True
            rewards[i] += rules.R_WIN - rules.R_COST * self.cost[i, t] / self.c_mean
        self.round += 1
        now_dec = self.deciding()
        finished = (not now_dec.any()) or not (req >= 0).any()
        truncated = (not finished) and self.round >= self.max_rounds
        self.done = finished or truncated
        if self.done:
            rewards[now_dec] += rules.R_STALL
        team = float(rewards.sum())
        if self.done:
            bonus = rules.team_bonus(int((self.agent_task >= 0).sum()), self.total(),
                                     self.opt_count, self.opt_total)
            rewards[dec] += bonus
            team += bonus
            ended = dec.copy()
        else:
            ended = dec & ~now_dec
        return rewards, team, dec, ended, self.done, truncated


def global_obs(game: Game) -> dict[str, np.ndarray]:
    """The observation arrays of the whole instance (every agent's local view is a masked part;
    see :func:`local_obs`)."""
    avail = game.available()
    status = game.deciding().astype(np.float32)
    agents = np.concatenate([status[:, None], game.flies[:, None].astype(np.float32),
                             game.agent_pos / game.world_size], axis=1)
    cost = np.where(avail, np.minimum(game.cost / rules.COST_SCALE, rules.COST_CAP),
                    rules.COST_CAP).astype(np.float32)
    tasks = np.concatenate([(~game.taken)[:, None].astype(np.float32),
                            game.task_pos / game.world_size], axis=1)
    return {"agents": agents.astype(np.float32), "cost": cost,
            "available": avail.astype(np.int8), "tasks": tasks.astype(np.float32),
            "adjacency": game.comm.astype(np.float32)}


def two_hop(comm: np.ndarray, i: int) -> tuple[np.ndarray, np.ndarray]:
    """Agents within one and within two hops of ``i`` (boolean masks, ``i`` included)."""
    one = comm[i].astype(bool).copy()
    one[i] = True
    two = one | comm[one].any(axis=0)
    return one, two


def local_obs(g: dict[str, np.ndarray], i: int, n_tasks: int) -> dict[str, np.ndarray]:
    """Agent ``i``'s observation: what its 2-hop neighbourhood tells it, zeros elsewhere."""
    adj = g["adjacency"].astype(bool)
    one, two = two_hop(adj, i)
    edge = (one[:, None] | one[None, :]) & adj & two[:, None] & two[None, :]
    me = np.zeros(len(adj), np.float32)
    me[i] = 1.0
    mask = np.concatenate([[1], g["available"][i]]).astype(np.int8)
    return {
        "agents": np.where(two[:, None], g["agents"], 0.0).astype(np.float32),
        "cost": np.where(two[:, None], g["cost"], rules.COST_CAP).astype(np.float32),
        "available": np.where(two[:, None], g["available"], 0).astype(np.int8),
        "tasks": g["tasks"],
        "adjacency": edge.astype(np.float32),
        "self": me,
        "action_mask": mask,
    }


class BatchedGame:
    """``B`` games of one size stepped together with tensors (same rules as :class:`Game`).

    Instances are set with :meth:`load` (all, or some slots: the trainer refills finished
    slots with fresh instances). Everything lives on the CPU in float32 except the costs.
    """

    def __init__(self, batch: int, n: int, m: int) -> None:
        self.B, self.n, self.m = batch, n, m
        self.cost = torch.zeros(batch, n, m, dtype=torch.float64)
        self.feasible = torch.zeros(batch, n, m, dtype=torch.bool)
        self.agent_pos = torch.zeros(batch, n, 3)
        self.task_pos = torch.zeros(batch, m, 3)
        self.flies = torch.zeros(batch, n, dtype=torch.bool)
        self.world_size = torch.ones(3)
        self.comm = torch.ones(batch, n, n, dtype=torch.bool)
        self.c_mean = torch.ones(batch, dtype=torch.float64)
        self.opt_count = torch.zeros(batch, dtype=torch.long)
        self.opt_total = torch.ones(batch, dtype=torch.float64)
        self.agent_task = torch.full((batch, n), -1, dtype=torch.long)
        self.taken = torch.zeros(batch, m, dtype=torch.bool)
        self.round = torch.zeros(batch, dtype=torch.long)
        self.conflicted = torch.zeros(batch, m, dtype=torch.bool)
        self.max_rounds = rules.max_rounds_for(m)

    def load(self, slots, cost, agent_pos, task_pos, flies, world_size, comm=None) -> None:
        slots = torch.as_tensor(slots, dtype=torch.long)
        cost = np.asarray(cost, np.float64)
        self.cost[slots] = torch.from_numpy(cost)
        self.feasible[slots] = torch.from_numpy(np.isfinite(cost))
        self.agent_pos[slots] = torch.as_tensor(np.asarray(agent_pos, np.float32))
        self.task_pos[slots] = torch.as_tensor(np.asarray(task_pos, np.float32))
        self.flies[slots] = torch.as_tensor(np.asarray(flies, bool))
        self.world_size = torch.as_tensor(np.asarray(world_size, np.float32))
        if comm is None:
            self.comm[slots] = True
        else:
            self.comm[slots] = torch.as_tensor(np.asarray(comm, bool))
        for k, s in enumerate(slots.tolist()):
            c = cost[k]
            fin = c[np.isfinite(c)]
            self.c_mean[s] = float(fin.mean()) if fin.size else 1.0
            cnt, tot = rules.optimal(c)
            self.opt_count[s], self.opt_total[s] = cnt, tot
        self.agent_task[slots] = -1
        self.taken[slots] = False
        self.round[slots] = 0
        self.conflicted[slots] = False

    def deciding(self) -> torch.Tensor:
        return (self.agent_task < 0) & (self.feasible & ~self.taken[:, None, :]).any(-1)

    def available(self) -> torch.Tensor:
        return self.feasible & ~self.taken[:, None, :] & (self.agent_task < 0)[:, :, None]

    def obs(self) -> dict[str, torch.Tensor]:
        """:func:`global_obs` of every game, stacked."""
        avail = self.available()
        status = self.deciding().float()
        agents = torch.cat([status[..., None], self.flies[..., None].float(),
                            self.agent_pos / self.world_size], -1)
        cost = torch.where(avail, (self.cost / rules.COST_SCALE).clamp(max=rules.COST_CAP),
                           torch.full_like(self.cost, rules.COST_CAP)).float()
        tasks = torch.cat([(~self.taken)[..., None].float(), self.task_pos / self.world_size], -1)
        return {"agents": agents, "cost": cost, "available": avail, "tasks": tasks,
                "adjacency": self.comm.float()}

    def totals(self) -> torch.Tensor:
        a = self.agent_task.clamp(min=0)
        c = torch.gather(self.cost, 2, a[..., None])[..., 0]
        return torch.where(self.agent_task >= 0, c, torch.zeros_like(c)).sum(1)

    def step(self, actions: torch.Tensor):
        """One round of every game; ``actions (B, N)`` in ``0..M``. Games already over must be
        reloaded first. Returns ``(rewards (B,N), team (B,), acted (B,N), ended (B,N),
        done (B,), truncated (B,))`` as :meth:`Game.step`."""
        B, n, m = self.B, self.n, self.m
        dec = self.deciding()
        avail = self.available()
        a = actions.long()
        t = (a - 1).clamp(min=0)
        ok = dec & (a > 0) & torch.gather(avail, 2, t[..., None])[..., 0]
        c_av = torch.where(avail, self.cost, torch.full_like(self.cost, float("inf")))
        has_av = avail.any(1)  # (B, M)
        owner = torch.where(has_av, c_av.argmin(1),
                            torch.full_like(has_av, -1, dtype=torch.long))
        owns = (owner[:, None, :] == torch.arange(n)[None, :, None]).any(2)  # (B, N)
        rewards = torch.where(dec & ~ok & owns, rules.R_REJECT, 0.0).double()
        onehot = torch.zeros(B, n, m, dtype=torch.bool)
        onehot.scatter_(2, t[..., None], ok[..., None])
        count = onehot.sum(1)  # (B, M)
        contested = torch.gather(count, 1, t) > 1
        self.conflicted |= count > 1
        masked = torch.where(onehot, self.cost, torch.full_like(self.cost, float("inf")))
        win_agent = masked.argmin(1)  # (B, M): first minimum = lowest index on ties
        has_req = count > 0
        won = torch.zeros(B, n, m, dtype=torch.bool)
        won.scatter_(1, win_agent[:, None, :], has_req[:, None, :])
        won &= onehot
        agent_won = won.any(2)
        pays = ok & contested & ~agent_won if rules.CONFLICT_LOSERS_ONLY else ok & contested
        rewards += torch.where(pays, rules.R_CONFLICT, 0.0)
        self.agent_task = torch.where(agent_won, won.float().argmax(2), self.agent_task)
        self.taken |= has_req
        c_win = torch.gather(self.cost, 2, t[..., None])[..., 0]
        rewards += torch.where(agent_won, rules.R_WIN - rules.R_COST * c_win /
                               self.c_mean[:, None], torch.zeros_like(c_win))
        self.round += 1
        now_dec = self.deciding()
        finished = ~now_dec.any(1) | ~ok.any(1)
        truncated = ~finished & (self.round >= self.max_rounds)
        done = finished | truncated
        rewards += torch.where(done[:, None] & now_dec, rules.R_STALL, 0.0)
        team = rewards.sum(1)
        n_assigned = (self.agent_task >= 0).sum(1)
        total = self.totals()
        gap = ((total - self.opt_total) / self.opt_total.clamp(min=1e-9)).clamp(min=0)
        bonus = torch.where(done & (n_assigned >= self.opt_count),
                            rules.R_TEAM * torch.exp(-rules.TEAM_SHARPNESS * gap),
                            torch.zeros_like(gap))
        rewards += torch.where(dec, bonus[:, None], torch.zeros_like(rewards))
        team += bonus
        self.last_bonus = bonus.float()
        ended = torch.where(done[:, None], dec, dec & ~now_dec)
        return rewards.float(), team.float(), dec, ended, done, truncated
