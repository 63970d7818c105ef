"""The paper's decision rounds and conflict rule, shared by every decentralized allocator.

In each round every agent that is still unassigned and still believes it has a feasible open
task either rejects (``-1``; the paper's action 0), waits (:data:`WAIT`: it requests nothing this
round but wants to decide later) or requests one task it believes open. A task
requested by several agents in the same round is a *conflict*: it goes to the requester with the
smallest cost (ties to the lowest agent index), the others stay unassigned and may request again
next round. Rounds repeat until no agent has anything left to request, no agent requests or
waits, or ``problem.max_rounds``. A round in which agents only wait sends no request (relays
still travel); an allocator that waits must stop waiting after a bounded number of rounds.

Putting the loop here means every decentralized method is measured the same way: the same
rounds, the same request log, the same conflict counting, the same communication model.

Communication model (see :mod:`dispatch.api.comms`)
    * **The arbiter at the task.** A request goes to the task, which settles it by the conflict
      rule and answers each requester (won, or lost: the task is taken). The arbiter is the
      ground truth: a task is never given twice, whatever the agents believe. A request for a
      task that was already won in an earlier round (by an agent that did not hear of it) loses
      and marks the task as conflicted. The request/answer exchange is reliable (acknowledged);
      ``loss`` applies to what agents learn from each other.
    * **Local knowledge.** Each agent knows which tasks are taken only from what reached it: its
      own answers from arbiters, and broadcasts of its neighbours. A request is one broadcast,
      heard by the arbiter and by the requester's neighbours; any request means the task is
      taken from the next round on (the conflict rule always gives a requested open task to
      someone), so a neighbour that hears it marks the task taken. News travels further by
      relays: an agent that learned something its own neighbours may have missed (it has a
      neighbour out of the sender's reach: the self-pruning rule of neighbour-knowledge
      flooding) passes it on in its next broadcast, piggybacked on its request if it makes one,
      else as a relay message of its own. One hop per round. ``choose`` sees each agent's belief:
      agents with the same belief are asked together, as before.
    * **Counting.** ``messages`` = requests (each sent whether or not the agent has neighbours:
      it is addressed to the arbiter) + relay-only broadcasts (only by agents with neighbours).
      On a complete graph without loss every agent hears every request, nobody relays, and the
      rounds, requests and messages are exactly those of a global-knowledge loop.
    * **Claims (optional).** An allocator whose :meth:`~DecentralizedAllocator.claim_steps` is
      positive precedes each round's requests by that many claim exchanges (see
      :func:`run_rounds`): intended requests are broadcast and relayed, a dearer claim on a task
      yields before it reaches the arbiter. Each exchange is one broadcast per agent with news
      (counted in ``messages``) and one hop. The default is none: nothing else changes.
    * **Latency.** A round is a request hop and an answer hop: ``hops = 2 * rounds`` (rounds in
      which someone requested or waited), plus one per claim exchange; the dispatcher turns that
      into simulated time.
    * **Compute time.** Each call of ``choose`` is timed and its seconds shared evenly among the
      agents it decided for: ``Allocation.agent_seconds``.
"""

from __future__ import annotations

import time
from abc import abstractmethod

import numpy as np

from dispatch.api.comms import Channel, relay_needed
from dispatch.api.contracts import Allocator
from dispatch.api.problem import Allocation, AllocationProblem, Bid
from dispatch.errors import AllocationError

#: What :meth:`DecentralizedAllocator.choose` returns for an agent that requests nothing this
#: round but is not done: unlike ``-1`` it keeps the rounds going when nobody requests.
WAIT = -2


class DecentralizedAllocator(Allocator):
    """Base class of allocators whose agents decide per round from their own information.

    Subclasses implement :meth:`choose`; they must not look at other agents' choices of the
    same round (that is what the conflict rule is for).
    """

    decentralized = True

    @abstractmethod
    def choose(
        self, problem: AllocationProblem, agents: np.ndarray, open_tasks: np.ndarray, round_: int
    ) -> np.ndarray:
        """Each agent's request this round.

        Args:
            problem: the decision (read-only).
            agents: indices (into ``problem.agents``) of the agents deciding this round. All of
                them hold the same belief ``open_tasks``; agents with different beliefs are
                asked in separate calls.
            open_tasks: boolean mask over ``problem.tasks`` of tasks these agents believe open
                (not known to be taken, from what reached them over the communication graph).
            round_: the round number, from 0.

        Returns:
            An int array aligned with ``agents``: a task index that is open in ``open_tasks``
            and feasible for that agent, ``-1`` to reject, or :data:`WAIT`.
        """

    def claim_steps(self, problem: AllocationProblem) -> int:
        """How many claim exchanges (see :func:`run_rounds`, ``claim_steps``) precede each
        round's requests; 0 (the default): none, agents request what ``choose`` said."""
        return 0

    def allocate(self, problem: AllocationProblem) -> Allocation:
        return run_rounds(problem, self.choose, claim_steps=self.claim_steps(problem))


def run_rounds(
    problem: AllocationProblem,
    choose,
    *,
    first: np.ndarray | None = None,
    known: np.ndarray | None = None,
    start_round: int = 0,
    claim_steps: int = 0,
) -> Allocation:
    """Run decision rounds with the conflict rule and the communication model.

    ``choose`` is :meth:`DecentralizedAllocator.choose`.

    Args:
        first: optional ``(N,)`` requests of round 0 (task index or ``-1`` per agent) that
            replace the call of ``choose`` in that round (an auction's claims); the entries of
            agents that are not deciding are ignored.
        known: optional ``(N, M)`` boolean "agent knows this task is taken" to start from.
        start_round: number of the first round in the request log (rounds already spent).
        claim_steps: before each round's requests, up to this many *claim exchanges*. Each
            agent keeps, per task, the cheapest claim (intended request) it knows of: its own
            and those its neighbours broadcast. In an exchange every agent whose table changed
            since its last broadcast (and that has neighbours) broadcasts it: one message each,
            one hop per exchange, ``loss`` applies. A claimant that learns of a cheaper claim on
            its task (ties to the lower index: the arbiter's own rule, so it would have lost)
            yields and is asked again (``choose``) with the tasks it knows claimed cheaper
            removed from what it believes open (nothing left: it waits). Exchanges stop when
            nobody has news. Claims travel one hop per exchange, so a request depends on what
            ``choose`` sees plus ``claim_steps`` hops.
    """
    n, m = problem.cost.shape
    feasible = problem.feasible
    agent_ids, task_ids = problem.agent_ids, problem.task_ids  # ids without building views
    # Everyone hears everyone and nothing is lost (unlimited range, the default): every
    # broadcast reaches every other agent and nobody relays, so a round's news is one OR over
    # the senders (the same beliefs as the general delivery below, without N x N work per
    # sender). Taxi studies decide among hundreds of idle vehicles at every request.
    complete = _everyone_hears(problem)
    # claim exchanges deliver through the channel even on a complete graph
    channel = None if complete and not claim_steps else Channel(problem.comm, problem.loss,
                                                                problem.rng)
    has_nb = np.full(n, n > 1) if complete else channel.has_neighbours()
    need_relay = None if complete or not n else relay_needed(problem.comm)
    known = np.zeros((n, m), dtype=bool) if known is None else np.array(known, dtype=bool)
    agent_task = np.full(n, -1, dtype=np.int64)
    taken = np.zeros(m, dtype=bool)  # the arbiters' truth
    relay = np.zeros((n, m), dtype=bool)  # news each agent passes on in its next broadcast
    seconds = np.zeros(n)
    requests: list[Bid] = []
    rounds = messages = hops = 0
    for r in range(problem.max_rounds):
        believed_open = ~known
        deciding = np.flatnonzero((agent_task < 0) & (feasible & believed_open).any(axis=1))
        if deciding.size == 0:
            break
        if r == 0 and first is not None:
            choice = np.asarray(first, dtype=np.int64)[deciding]
        else:
            choice = _choose_local(problem, choose, deciding, believed_open, start_round + r,
                                   seconds)
        if claim_steps and not (r == 0 and first is not None):
            sent, steps = _exchange_claims(problem, choose, channel, has_nb=has_nb,
                                           deciding=deciding, believed_open=believed_open,
                                           choice=choice, round_=start_round + r,
                                           seconds=seconds, steps=claim_steps)
            messages += sent
            hops += steps
        rounds = r + 1
        asked = choice >= 0
        if not asked.any() and not (choice == WAIT).any():
            break
        req_agents, req_tasks = deciding[asked], choice[asked]
        ok = req_tasks < m
        ok[ok] = believed_open[req_agents[ok], req_tasks[ok]] \
            & feasible[req_agents[ok], req_tasks[ok]]
        if not ok.all():
            k = int(np.flatnonzero(~ok)[0])
            raise AllocationError(
                f"agent {problem.agents[req_agents[k]].id} requested task index "
                f"{req_tasks[k]}, which is not an open task it can serve"
            )
        fresh = ~taken[req_tasks]
        winners = resolve_conflicts(problem.cost, req_agents[fresh], req_tasks[fresh])
        # the log, built from whole arrays (a taxi decision logs hundreds of requests)
        rnd = start_round + r
        for a, t, aid, tid, c in zip(req_agents.tolist(), req_tasks.tolist(),
                                     agent_ids[req_agents].tolist(),
                                     task_ids[req_tasks].tolist(),
                                     problem.cost[req_agents, req_tasks].tolist()):
            requests.append(Bid(rnd, aid, tid, c, winners.get(t) == a))
        for t, a in winners.items():
            agent_task[a] = t
            taken[t] = True
        known[req_agents, req_tasks] = True  # the arbiter's answer
        # Broadcasts: every request (with any pending relay piggybacked), and relay-only
        # messages from agents that have news and neighbours.
        news = relay.copy()
        news[req_agents, req_tasks] = True
        relay_only = np.flatnonzero(news.any(axis=1) & has_nb)
        relay_only = relay_only[~np.isin(relay_only, req_agents)]
        messages += int(req_agents.size + relay_only.size)
        senders = np.union1d(req_agents, relay_only)
        if complete:  # relay stays empty: a sender's own news is already in its row
            if senders.size and n > 1:
                known |= news[senders].any(axis=0)[None, :]
            hops += 2
            continue
        got = channel.deliver(senders)
        relay = np.zeros((n, m), dtype=bool)
        for k in senders:
            rec = np.flatnonzero(got[k])
            if rec.size == 0:
                continue
            new = news[k][None, :] & ~known[rec]
            known[rec] |= news[k][None, :]
            relay[rec] |= new & need_relay[k, rec][:, None]
        hops += 2
    got = np.flatnonzero(agent_task >= 0)
    pairs = tuple(zip(agent_ids[got].tolist(), task_ids[agent_task[got]].tolist()))
    return Allocation(pairs=pairs, rounds=rounds, requests=tuple(requests), messages=messages,
                      hops=hops, agent_seconds=tuple(seconds.tolist()))


def _everyone_hears(problem: AllocationProblem) -> bool:
    """Whether every broadcast reaches every other agent: a complete graph, no loss."""
    if problem.loss > 0:
        return False
    comm = np.asarray(problem.comm)
    if comm.size and not any(comm.strides):  # one value broadcast (the dispatcher's "all")
        return bool(comm.flat[0])
    return bool(comm.all())


def _choose_local(problem, choose, deciding, believed_open, round_, seconds) -> np.ndarray:
    """Ask ``choose`` once per group of deciding agents that share a belief (one call when
    everyone knows the same, as on a complete graph)."""
    rows = believed_open[deciding]
    if len(rows) and (rows == rows[0]).all():
        groups = [np.arange(len(deciding))]
    else:
        _, first_at, inverse = np.unique(rows, axis=0, return_index=True, return_inverse=True)
        inverse = np.asarray(inverse).reshape(-1)
        groups = [np.flatnonzero(inverse == g) for g in np.argsort(first_at)]
    choice = np.full(len(deciding), -1, dtype=np.int64)
    for pos in groups:
        members = deciding[pos]
        t0 = time.perf_counter()
        c = np.asarray(choose(problem, members, rows[pos[0]].copy(), round_), dtype=np.int64)
        seconds[members] += (time.perf_counter() - t0) / len(members)
        if c.shape != members.shape:
            raise AllocationError(
                f"choose() returned {c.shape[0] if c.ndim else 'a scalar'} "
                f"requests for {members.size} deciding agents"
            )
        choice[pos] = c
    return choice


def _exchange_claims(problem, choose, channel, *, has_nb, deciding, believed_open, choice, round_,
                     seconds, steps: int) -> tuple[int, int]:
    """The claim exchanges of one round (see :func:`run_rounds`); updates ``choice`` in place
    and returns ``(messages, hops)``.

    Each agent keeps, per task, the cheapest claim it knows of (cost, agent): its own, and what
    its neighbours' last broadcasts held. An exchange is one broadcast of that table by every
    agent that knows a claim (and has neighbours), so claims travel one hop per exchange."""
    cost = problem.cost
    n, m = cost.shape
    inf = np.inf
    messages = hops = 0
    table_c = np.full((n, m), inf)  # cheapest claim known per (agent, task)
    table_a = np.full((n, m), n, dtype=np.int64)  # its claimant (n: none)
    sent_c, sent_a = table_c.copy(), table_a.copy()  # what each agent broadcast last
    for _ in range(steps):
        own_c, own_a = np.full((n, m), inf), np.full((n, m), n, dtype=np.int64)
        claim = choice >= 0
        cl, ct = deciding[claim], choice[claim]
        own_c[cl, ct], own_a[cl, ct] = cost[cl, ct], cl
        # what each agent broadcasts: its own claim merged with what it knew
        send_c, send_a = _cheaper(table_c, table_a, own_c, own_a)
        # only an agent whose table changed since its last broadcast has news
        fresh = ((send_c != sent_c) | (send_a != sent_a)).any(axis=1)
        senders = np.flatnonzero(fresh & has_nb)
        if senders.size == 0:
            break
        sent_c[senders], sent_a[senders] = send_c[senders], send_a[senders]
        got = channel.deliver(senders)
        messages += int(senders.size)
        hops += 1
        table_c, table_a = send_c.copy(), send_a.copy()  # what is sent stays as it was sent
        for k in senders.tolist():
            rec = np.flatnonzero(got[k])
            if rec.size:
                table_c[rec], table_a[rec] = _cheaper(table_c[rec], table_a[rec],
                                                      send_c[k][None, :], send_a[k][None, :])
        # a claimant yields to a cheaper claim it knows on its task
        lose = claim & (table_a[deciding, np.maximum(choice, 0)] != deciding)
        if not lose.any():
            continue
        losers = np.flatnonzero(lose)
        again = deciding[losers]
        mine = cost[again]
        beaten = believed_open.copy()
        beaten[again] = (table_c[again] < mine) | ((table_c[again] == mine)
                                                   & (table_a[again] < again[:, None]))
        belief = believed_open.copy()
        belief[again] &= ~beaten[again]
        new = np.full(len(losers), WAIT, dtype=np.int64)  # nothing left this round: wait
        ok = (belief[again] & problem.feasible[again]).any(axis=1)
        if ok.any():
            new[ok] = _choose_local(problem, choose, again[ok], belief, round_, seconds)
        choice[losers] = new
    return messages, hops


def _cheaper(c1, a1, c2, a2):
    """Entry-wise the cheaper of two claim tables (ties to the lower agent index)."""
    take = (c2 < c1) | ((c2 == c1) & (a2 < a1))
    return np.where(take, c2, c1), np.where(take, a2, a1)


def resolve_conflicts(cost: np.ndarray, agents: np.ndarray, tasks: np.ndarray
                      ) -> dict[int, int]:
    """The conflict rule: for each requested task, the requester with the smallest cost."""
    best: dict[int, tuple[float, int]] = {}  # task -> (cost, agent) of its best requester
    for a, t, c in zip(agents.tolist(), tasks.tolist(), cost[agents, tasks].tolist()):
        held = best.get(t)
        if held is None or (c, a) < held:
            best[t] = (c, a)
    return {t: a for t, (_, a) in best.items()}
