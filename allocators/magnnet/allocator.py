"""The ``magnnet`` allocator plugin: trained MAGNNET policies, executed decentralized.

Each deciding agent builds the observation of :mod:`allocators.magnnet.game` from what it knows
(its own costs, task positions and which tasks it believes open, and what its communication
neighbours broadcast), runs the graph network over its neighbourhood and takes the most likely
action of its policy: reject, or request one task. Rounds and conflicts are the shared ones of
:class:`~dispatch.decentralized.DecentralizedAllocator`. For speed every deciding agent of a
call is evaluated in one batched pass over the problem's graph; the network only mixes
information along communication links (two hops), so each agent's action is the one it would
compute alone from its own neighbourhood (tests check it).

Parameters (``[dispatch.allocator_params]``):
    variant: ``"paper"`` (the paper's model exactly, one checkpoint per size N = M),
        ``"paper_nb"`` (the paper's model plus per-task features from the neighbours' cost
        vectors in the actor's input: our addition, one checkpoint per size), ``"edge"`` (the
        size-agnostic edge-scoring model, any N and M), ``"edge_noassign"`` (the edge model
        without its hand-written local-assignment feature: an ablation) or ``"auto"``
        (default: ``paper_nb`` when a checkpoint for the problem's N x M ships, else the edge
        model).
    checkpoint: path of a checkpoint to use instead of the shipped ones.

Checkpoints ship in ``allocators/magnnet/checkpoints`` (``paper_n{N}.pt``,
``paper_nb_n{N}.pt``, ``edge.pt``, ``edge_noassign.pt``, ``match.pt``).

The ``magnnet_match`` plugin (:class:`MagnnetMatchAllocator`) runs the size-agnostic
agent-task graph network of :mod:`allocators.magnnet.match`, trained to imitate the optimal
assignment, with mutual-best requests.
"""

from __future__ import annotations

from functools import lru_cache
from pathlib import Path

import numpy as np

from dispatch.contracts import AllocationProblem
from dispatch.decentralized import DecentralizedAllocator
from dispatch.errors import AllocationError

CHECKPOINTS = Path(__file__).resolve().parent / "checkpoints"
#: Positions are divided by the size of the world the shipped models were trained in.
TRAIN_WORLD = np.array([50.0, 50.0, 30.0], np.float32)


@lru_cache(maxsize=16)
def _load(path: str):
    import torch

    from allocators.magnnet.ppo import load_checkpoint

    torch.set_num_threads(1)
    model, ck = load_checkpoint(path)
    size = np.asarray(ck.get("extra", {}).get("world_size", TRAIN_WORLD), np.float32)
    return model, size


VARIANTS = ("auto", "paper", "paper_nb", "edge", "edge_noassign")


def check_checkpoint(checkpoint, allocator: str, match: bool) -> str:
    """Check a ``checkpoint`` parameter when the allocator is built (not in its first
    decision): a path to a file that loads with ``torch.load(weights_only=True)`` as a model
    of the right kind (``match`` or not). ValueError naming the file and what is wrong."""
    import os

    if isinstance(checkpoint, bool) or not isinstance(checkpoint, (str, os.PathLike)) \
            or not str(checkpoint):
        raise ValueError(f"checkpoint must be the path of a model.pt, got {checkpoint!r}")
    path = Path(checkpoint)
    if not path.is_file():
        raise ValueError(f"checkpoint {path}: no such file")
    try:
        model, _ = _load(str(path))
    except Exception as e:  # noqa: BLE001 - torch and the model raise many kinds
        first = (str(e).strip().splitlines() or [""])[0][:200]
        raise ValueError(f"checkpoint {path} is not a MAGNNET checkpoint (torch.load with "
                         f"weights_only=True and the model failed: {type(e).__name__}: "
                         f"{first})") from None
    kind = getattr(model, "variant", None)
    if match and kind != "match":
        raise ValueError(f"checkpoint {path} holds a model of kind {kind!r}; {allocator} needs a "
                         "'match' one (dispatch train magnnet --variant match)")
    if not match and kind == "match":
        raise ValueError(f"checkpoint {path} holds a model of kind 'match'; use it with "
                         "allocator = 'magnnet_match'")
    return str(path)


def shipped(variant: str, n: int | None = None) -> Path:
    if variant in ("paper", "paper_nb"):
        return CHECKPOINTS / f"{variant}_n{n}.pt"
    return CHECKPOINTS / f"{variant}.pt"


class MagnnetAllocator(DecentralizedAllocator):
    """MAGNNET (Ratnabala et al. 2025): GNN + MLP policy per agent, trained with CTDE PPO."""

    name = "magnnet"

    def __init__(self, variant: str = "auto", checkpoint: str | None = None) -> None:
        if variant not in VARIANTS:
            raise TypeError(f"variant must be one of {VARIANTS}, got {variant!r}")
        self.variant = variant
        if checkpoint is not None:
            check_checkpoint(checkpoint, self.name, match=False)
        self.checkpoint = checkpoint

    def model_for(self, n: int, m: int):
        if self.checkpoint is not None:
            path = Path(self.checkpoint)
        elif self.variant in ("edge", "edge_noassign"):
            path = shipped(self.variant)
        elif self.variant == "auto":
            path = shipped("paper_nb", n)
            if n != m or not path.exists():
                path = shipped("edge")
        else:
            path = shipped(self.variant, n)
        if not path.exists():
            raise AllocationError(f"magnnet: no checkpoint at {path} (variant {self.variant!r}, "
                                  f"N={n}, M={m}); train one with `dispatch train magnnet`")
        model, size = _load(str(path))
        if model.variant.startswith("paper") and (model.n_agents, model.n_tasks) != (n, m):
            raise AllocationError(
                f"magnnet: checkpoint {path.name} is for N={model.n_agents}, M={model.n_tasks}, "
                f"the problem is N={n}, M={m}; use variant='edge' for other sizes")
        return model, size

    def choose(self, problem: AllocationProblem, agents: np.ndarray, open_tasks: np.ndarray,
               round_: int) -> np.ndarray:
        import torch

        n, m = problem.cost.shape
        model, size = self.model_for(n, m)
        obs = observe(problem, agents, open_tasks, size)
        with torch.no_grad():
            logits, _ = model(obs)
        act = logits[0].argmax(-1).numpy()[agents]
        return np.where(act > 0, act - 1, -1)


class MagnnetEdgeAllocator(MagnnetAllocator):
    """MAGNNET, size-agnostic variant: scores every agent-task edge; one model for any N, M."""

    name = "magnnet_edge"

    def __init__(self, checkpoint: str | None = None) -> None:
        super().__init__("edge", checkpoint)


class MagnnetMatchAllocator(DecentralizedAllocator):
    """MAGNNET-match: edge scores from a bipartite graph network over each agent's view, and
    mutual-best requests (see :mod:`allocators.magnnet.match`).

    An agent's view is the deciding agents within two communication hops and the tasks it
    believes open; it computes the scores of its whole view (its neighbours' cost vectors come
    over the links) and requests its best task only if no agent of the view scores that task
    higher and, if it hears the whole fleet (so that every agent shares its view), the model
    is confident of the pair (see :func:`~allocators.magnnet.match.mutual_best`). An agent that
    does not hear the whole fleet skips the confidence test and requests its best task
    regardless from round ``patience`` on, so a decision under partial communication cannot
    stall; the conflict rule settles what follows.

    Parameters (``[dispatch.allocator_params]``): ``checkpoint`` (default: the shipped
    ``match.pt``), ``confidence`` (in ``[0, 1]``, default 0.8; 0: plain mutual best),
    ``patience`` (default 3).
    """

    name = "magnnet_match"

    def __init__(self, checkpoint: str | None = None, confidence: float = 0.8,
                 patience: int = 3) -> None:
        if isinstance(patience, bool) or not isinstance(patience, int) or patience < 0:
            raise TypeError(f"patience must be a non-negative integer, got {patience!r}")
        if (isinstance(confidence, bool) or not isinstance(confidence, (int, float))
                or not 0.0 <= confidence <= 1.0):
            raise TypeError(f"confidence must be a number in [0, 1], got {confidence!r}")
        if checkpoint is not None:
            check_checkpoint(checkpoint, self.name, match=True)
        self.checkpoint = checkpoint
        self.confidence = float(confidence)
        self.patience = patience

    def model(self):
        path = Path(self.checkpoint) if self.checkpoint is not None else shipped("match")
        if not path.exists():
            raise AllocationError(f"magnnet_match: no checkpoint at {path}; train one with "
                                  "`dispatch train magnnet --variant match`")
        model, _ = _load(str(path))
        if model.variant != "match":
            raise AllocationError(f"magnnet_match: {path.name} holds a {model.variant!r} "
                                  "model, not a 'match' one")
        return model

    def choose(self, problem: AllocationProblem, agents: np.ndarray, open_tasks: np.ndarray,
               round_: int) -> np.ndarray:
        from allocators.magnnet.game import two_hop
        from allocators.magnnet.match import mutual_best, scores_of

        model = self.model()
        comm = problem.comm.astype(bool)
        deciding = np.zeros(problem.cost.shape[0], bool)
        deciding[agents] = True
        flies = np.array([a.flies for a in problem.agents], bool)
        tasks = np.flatnonzero(open_tasks)
        out = np.full(len(agents), -1, np.int64)
        views: dict[bytes, tuple[np.ndarray, list[int]]] = {}
        for k, i in enumerate(agents):
            _, two = two_hop(comm, int(i))
            members = np.flatnonzero(two & deciding)
            views.setdefault(members.tobytes(), (members, []))[1].append(k)
        # an agent that hears every vehicle directly knows its view is everyone's: no forcing
        hears_all = comm[agents].all(axis=1)
        late = round_ >= self.patience
        # agents that share a view share one forward pass (one for everyone on a complete graph)
        for members, ks in views.values():
            scores = scores_of(model, problem.cost[np.ix_(members, tasks)], flies[members])
            ks = np.asarray(ks)
            # waiting for confidence pays only where every agent shares one view; with partial
            # views it only delays agents while others go ahead
            for full in (True, False):
                sel = ks[hears_all[ks] == full]
                if sel.size == 0:
                    continue
                req = mutual_best(scores, np.searchsorted(members, agents[sel]),
                                  force=late and not full,
                                  confidence=self.confidence if full else 0.0)
                out[sel] = np.where(req >= 0, tasks[np.maximum(req, 0)], -1)
        return out


def observe(problem: AllocationProblem, agents: np.ndarray, open_tasks: np.ndarray,
            world_size: np.ndarray) -> dict:
    """The batched observation (batch of one) of the deciding ``agents`` that believe
    ``open_tasks`` open (see :func:`allocators.magnnet.game.global_obs`)."""
    import torch

    from allocators.magnnet import rules

    n, m = problem.cost.shape
    deciding = np.zeros(n, bool)
    deciding[agents] = True
    avail = problem.feasible & open_tasks[None, :] & deciding[:, None]
    apos = problem.agent_pos.astype(np.float32)  # metres, from the run's space
    tpos = problem.task_pos.astype(np.float32)
    flies = np.array([a.flies for a in problem.agents], np.float32)
    agent_f = np.concatenate([deciding[:, None].astype(np.float32), flies[:, None],
                              apos / world_size], 1)
    cost = np.where(avail, np.minimum(problem.cost / rules.COST_SCALE, rules.COST_CAP),
                    rules.COST_CAP).astype(np.float32)
    task_f = np.concatenate([open_tasks[:, None].astype(np.float32), tpos / world_size], 1)
    t = lambda x: torch.from_numpy(np.ascontiguousarray(x))[None]  # noqa: E731
    return {"agents": t(agent_f), "cost": t(cost), "available": t(avail),
            "tasks": t(task_f), "adjacency": t(problem.comm.astype(np.float32))}
