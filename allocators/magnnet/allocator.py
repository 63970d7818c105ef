"""The ``magnnet`` allocator plugin: trained MAGNNET policies, executed decentralized.

One plugin, one name; its ``variant`` says which network runs, and the run's ``summary``
(column ``allocator_info``) and Parquet metadata record the model, the variant and the
checkpoint files with their SHA-256 (see :meth:`MagnnetAllocator.describe`).

Variants (``[dispatch.allocator_params] variant = ...``):

``"match"`` (default)
    The size-agnostic agent-task graph network (:mod:`allocators.magnnet.match`), trained by
    imitation of the optimal assignment; any ``N`` and ``M``. An agent that hears the whole
    fleet scores the whole problem with ``match.pt`` and requests its best task when the pair
    is mutual best and confident (conflict-free by construction, since every such agent shares
    the one view).

    Under a limited range each decision starts with ``view_hops`` (default 6) flooding steps
    (:func:`flood`): every agent with news broadcasts what it knows (its own and the others'
    cost vectors and neighbour lists), so an agent learns everyone within ``view_hops`` hops.
    One that then sees its whole component (no member it knows of has a neighbour outside)
    knows what every other agent of the component knows in round 0 (the same agents, every
    task open), plays the match model's decision rounds on the component (:func:`match.plan`)
    and requests its own part: the agents of a component request one conflict-free plan, and
    conflicts can only come from another component. The flooding is counted in ``messages``
    (one per agent with news and neighbours per step) and ``hops`` (``view_hops``); the
    two-hop view gathering of the rule below was never counted, as before.
    ``view_hops = 2`` turns this off (the rule of the previous version, ``magnnet:view2`` in
    ``benchmarks/paper_tables.py``).

    An agent that does not know its whole component (and every agent after round 0) acts on its
    two-hop view with the view model ``view.pt`` (:mod:`allocators.magnnet.views`: the match network
    plus the
    view's hop, status and size features and "not mine / outside my view" heads, trained
    CTDE with DAgger for partial views); it waits while unsure and must request from round
    ``view_patience`` on. ``partial = "match"`` runs ``match.pt`` on partial views instead (what
    the plugin did before the view model: an ablation).
``"paper"``
    The paper's network exactly (two 6-unit graph convolutions, MLP actor over
    ``[status, M costs, embedding]``), trained with the paper's PPO; one checkpoint per size
    ``N = M`` (``paper_n{N}.pt``). A problem of a size without a checkpoint is an error.
``"paper_nb"``
    The paper's network plus per-task features from the neighbours' broadcast cost vectors in
    the actor's input (our addition); one checkpoint per size (``paper_nb_n{N}.pt``), same
    rule. Before the plugin was unified this was what ``magnnet`` ran at ``N = M``.

``"ppo"``
    The attention policy trained by PPO alone (issue 33, :mod:`allocators.magnnet.attention`:
    agent-task pairs attend over their agent's tasks and over the agents in radio range; no
    imitation, no teacher), one checkpoint ``ppo.pt`` for every size. Each round the deciding
    agents of a belief score their observation (:func:`~allocators.magnnet.attention.observe`)
    and act by :func:`~allocators.magnnet.attention.decide`, the function the training
    environment (:mod:`allocators.magnnet.ppo_env`) plays: wait, or request one task.

Look-ahead (issue 22): ``value`` (a file of ``dispatch train value``) and ``value_weight``, as
``hungarian``'s (:class:`learning.value.ValueOption`): each agent's costs become its travel
times less the discounted value of where each trip leaves it plus its value now; variant
``match`` only.

Other parameters: ``checkpoint`` (a ``model.pt`` of ``dispatch train magnnet`` replacing the
shipped one of the variant: a match model for ``match``, a paper model of one size for
``paper``/``paper_nb``), ``view_checkpoint`` (replaces ``view.pt``), ``view_weights`` (default
``"auto"``: which view model scores a partial view; ``view_taxi.pt``, the view model retrained
by DAgger on Chicago taxi decisions under a 2 km range, :mod:`allocators.magnnet.view_taxi`,
on a view out of the training range by the test of ``cost_scale = "auto"`` below (median
travel time above :data:`TRAIN_MAX_S`: a city's taxis), ``view.pt`` on the others, so the
paper's instances run as before; ``"view"`` / ``"taxi"``: that model on every partial view),
``taxi_view_checkpoint`` (replaces ``view_taxi.pt``), ``confidence`` (default
0.8: row and column softmax a pair needs before an agent that hears everyone requests it),
``view_confidence`` (default 0.5: the same for the view model), ``patience`` (default 3: the
round from which the match model on partial views, ``partial = "match"``, requests regardless),
``view_patience`` (default 12: the round from which the view model requests its part of its
view's assignment, and from twice that its best task regardless), ``view_hops`` (default 6,
at least 2: see above), ``claims`` (default 0: claim exchanges before each round's requests,
:func:`dispatch.api.decentralized.run_rounds`; measured: they raise the conflict-free share of the
two-hop rule but not its gap, and add nothing once the views are flooded),
``cost_scale`` (default
``"auto"``: a view whose median travel time exceeds :data:`TRAIN_MAX_S`, 30 s, the longest the
training instances hold, e.g. a city's taxis several minutes away, is fed to the match and view
models rescaled so that its median is :data:`TRAIN_MEDIAN_S`, the training instances' median;
on Chicago decisions this cut the gap to the optimal assignment from 11.4 % to 4.0 %; the
conflict rule still reads the real costs; a number: seconds per model second, 1 = raw),
``candidates`` (default ``"auto"``: on such a view, each task keeps only the edges of its
:data:`CANDIDATES` cheapest agents, and only agents kept by some task are scored and may request
this round; the others are considered again next round, when the pairs settled leave room; an
integer: always that many, 0: everyone), ``view_candidates`` (default ``"auto"``: the same cut
for the view model's two-hop views, on a view out of the training range: each task keeps its
:data:`CANDIDATES` cheapest deciding agents of the view, and the agents that stopped deciding
and are no dearer than those; an agent cut out of its own view requests nothing that round and
needs no network call; an integer: always that many; 0: the whole view, the rule before it. On
a city's taxis at 2 km a two-hop view holds hundreds of taxis, ten times the training views:
on five night decisions of the Chicago study at N = 500 the whole views gave 375 % mean gap to
the optimal assignment in 18 rounds, the cut views 81 % in 4, at an eighteenth of the compute
(means over the four decisions where both assigned as many pairs as the optimum; ``auction``
and ``local_hungarian``: 0.0 %). On the paper's instances (costs of seconds) nothing is cut:
its results do not change).

Under a limited range a decision round scores the views of all its agents in one pass
(:func:`allocators.magnnet.views.view_scores_many`: the same numbers as one call per view, up
to the order of float sums), the agents a cut leaves out are found for all agents at once, and
the two-hop neighbourhoods and the flooding are float32 matrix products (exact counts).

Large sparse problems (a request reaches a few percent of a city's idle taxis within its
``max_wait``) are scored on their feasible edges only
(:func:`allocators.magnnet.match.sparse_scores`: the same network, the same numbers up to the
order of float sums).

Every model is read from disk and run once (warm-up) in the constructor, so a decision never
includes imports or file reads. Loaded models are cached per file for the process;
:func:`clear_model_cache` empties the cache (benchmarks that measure a cold start call it).
"""

from __future__ import annotations

import hashlib
import re
from functools import lru_cache
from pathlib import Path

import numpy as np

from dispatch.api.decentralized import DecentralizedAllocator
from dispatch.api.problem import AllocationProblem
from dispatch.errors import AllocationError

CHECKPOINTS = Path(__file__).resolve().parent / "checkpoints"
#: Positions are divided by the size of the world the shipped models were trained in.
TRAIN_WORLD = np.array([50.0, 50.0, 30.0], np.float32)
VARIANTS = ("match", "paper", "paper_nb", "ppo")
#: The training instances' travel times (paper_static, N = 20 pool): median 7.3 s, largest
#: 25.2 s. A view whose median cost exceeds TRAIN_MAX_S (a city's taxis: minutes) is out of
#: that range; ``cost_scale = "auto"`` rescales it so its median is TRAIN_MEDIAN_S.
TRAIN_MEDIAN_S = 7.3
TRAIN_MAX_S = 30.0
#: ``candidates = "auto"`` on such a view: each task's 4 cheapest agents (the training
#: instances hold at most 50 agents, a city's idle fleet hundreds). Chosen on 160 Chicago
#: decisions (N = 500 at 7-9 h, N = 1000 at 0-2 h; mean gap to the optimal assignment):
#: 4: 1.4 % / 2.7 %, 8: 1.4 % / 8.1 %, 16: 2.3 % / 13.8 %, 32: 2.4 % / 37.9 %, all agents:
#: 4.0 % / 154 % (greedy: 0.2 % / 15.9 %).
CANDIDATES = 4
PARTIAL = ("view", "match")
#: ``view_weights``: which view model scores a partial view. ``"auto"``: ``view_taxi.pt`` on a
#: view out of the training range (the test of ``cost_scale = "auto"``: median travel time above
#: TRAIN_MAX_S, a city's taxis), ``view.pt`` on the others (the paper's instances: unchanged);
#: ``"view"`` / ``"taxi"``: that model on every partial view.
VIEW_WEIGHTS = ("auto", "view", "taxi")


@lru_cache(maxsize=32)
def _load(path: str):
    import torch

    from allocators.magnnet.ppo import load_checkpoint

    torch.set_num_threads(1)
    model, ck = load_checkpoint(path)
    size = np.asarray(ck.get("extra", {}).get("world_size", TRAIN_WORLD), np.float32)
    return model, size, _sha(path)


def _sha(path: str) -> str:
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()[:16]


def clear_model_cache() -> None:
    """Forget every loaded model: the next allocator built reads its files again."""
    _load.cache_clear()


def load_model(checkpoint, allocator: str, kinds: tuple[str, ...]):
    """``(model, world size, sha)`` of a checkpoint file whose model is of one of ``kinds``.
    ValueError naming the file and what is wrong (missing, not a checkpoint, wrong kind)."""
    import os

    if isinstance(checkpoint, bool) or not isinstance(checkpoint, (str, os.PathLike)) \
            or not str(checkpoint):
        raise ValueError(f"checkpoint must be the path of a model.pt, got {checkpoint!r}")
    path = Path(checkpoint)
    if not path.is_file():
        raise ValueError(f"checkpoint {path}: no such file")
    try:
        model, size, sha = _load(str(path))
    except Exception as e:  # noqa: BLE001 - torch and the model raise many kinds
        first = (str(e).strip().splitlines() or [""])[0][:200]
        raise ValueError(f"checkpoint {path} is not a MAGNNET checkpoint (torch.load with "
                         f"weights_only=True and the model failed: {type(e).__name__}: "
                         f"{first})") from None
    kind = getattr(model, "variant", None)
    if kind == "paper" and getattr(model, "task_features", 0):
        kind = "paper_nb"
    if kind not in kinds:
        raise ValueError(f"checkpoint {path} holds a model of kind {kind!r}; {allocator} needs "
                         f"{' or '.join(repr(k) for k in kinds)} here")
    return model, size, sha


def shipped(variant: str, n: int | None = None) -> Path:
    """The shipped checkpoint of a variant (``paper``/``paper_nb``: of size ``n``)."""
    if variant in ("paper", "paper_nb"):
        return CHECKPOINTS / f"{variant}_n{n}.pt"
    return CHECKPOINTS / f"{variant}.pt"


def shipped_sizes(variant: str) -> list[int]:
    """The sizes ``N = M`` for which a checkpoint of ``variant`` ships."""
    pat = re.compile(rf"{re.escape(variant)}_n(\d+)\.pt$")
    return sorted(int(m.group(1)) for p in CHECKPOINTS.glob(f"{variant}_n*.pt")
                  if (m := pat.match(p.name)))


def _number(value, name: str, low: float, high: float) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) \
            or not low <= value <= high:
        raise TypeError(f"{name} must be a number in [{low:g}, {high:g}], got {value!r}")
    return float(value)


class MagnnetAllocator(DecentralizedAllocator):
    """MAGNNET: a trained graph-network policy per agent (variant match, paper or paper_nb).

    Ratnabala et al. 2025. Variant ``match`` (default, any size) or the paper's network,
    ``paper`` / ``paper_nb`` (one checkpoint per N = M); see the module doc."""

    name = "magnnet"
    variants = VARIANTS

    def __init__(self, variant: str = "match", checkpoint: str | None = None,
                 view_checkpoint: str | None = None, partial: str = "view",
                 confidence: float = 0.8, view_confidence: float = 0.5,
                 patience: int = 3, view_patience: int = 12, view_hops: int = 6,
                 claims: int = 0, cost_scale: str | float = "auto",
                 candidates: str | int = "auto", view_candidates: str | int = "auto",
                 value: str | None = None, value_weight: float | None = None,
                 view_weights: str = "auto", taxi_view_checkpoint: str | None = None) -> None:
        if variant not in VARIANTS:
            raise TypeError(f"variant must be one of {', '.join(VARIANTS)}, got {variant!r}")
        if partial not in PARTIAL:
            raise TypeError(f"partial must be one of {', '.join(PARTIAL)}, got {partial!r}")
        for name, number in (("patience", patience), ("view_patience", view_patience),
                             ("claims", claims)):
            if isinstance(number, bool) or not isinstance(number, int) or number < 0:
                raise TypeError(f"{name} must be a non-negative integer, got {number!r}")
        if isinstance(view_hops, bool) or not isinstance(view_hops, int) or view_hops < 2:
            raise TypeError(f"view_hops must be an integer >= 2, got {view_hops!r}")
        self.variant, self.partial, self.patience = variant, partial, patience
        self.view_patience, self.claims, self.view_hops = view_patience, claims, view_hops
        self._plans, self._known, self._complete = {}, None, None  # per decision (allocate)
        self._two = self._two_done = self._flies_all = None  # per decision (allocate)
        if cost_scale != "auto" and (isinstance(cost_scale, bool) or not isinstance(
                cost_scale, (int, float)) or not 0 < cost_scale < float("inf")):
            raise TypeError(f"cost_scale must be 'auto' or a number > 0, got {cost_scale!r}")
        self.cost_scale = cost_scale
        if candidates != "auto" and (isinstance(candidates, bool)
                                     or not isinstance(candidates, int) or candidates < 0):
            raise TypeError(f"candidates must be 'auto' or an integer >= 0, got {candidates!r}")
        self.candidates = candidates
        if view_candidates != "auto" and (isinstance(view_candidates, bool) or not isinstance(
                view_candidates, int) or view_candidates < 0):
            raise TypeError(f"view_candidates must be 'auto' or an integer >= 0, got "
                            f"{view_candidates!r}")
        self.view_candidates = view_candidates
        if view_weights not in VIEW_WEIGHTS:
            raise TypeError(f"view_weights must be one of {', '.join(VIEW_WEIGHTS)}, got "
                            f"{view_weights!r}")
        self.view_weights = view_weights
        self.confidence = _number(confidence, "confidence", 0.0, 1.0)
        self.view_confidence = _number(view_confidence, "view_confidence", 0.0, 1.0)
        if variant != "match" and (view_checkpoint is not None or partial != "view"
                                   or taxi_view_checkpoint is not None):
            raise TypeError(f"view_checkpoint, taxi_view_checkpoint and partial apply to "
                            f"variant 'match' only, not {variant!r}")
        self._record = None  # DAgger: a list that collects the views decided on
        self.value = None
        if value is not None:  # the look-ahead option shared with hungarian (learning.value)
            if variant != "match":
                raise TypeError(f"value applies to variant 'match' only, not {variant!r}")
            from learning.value import ValueOption

            self.value = ValueOption(value, value_weight)
            self.value_function = self.value.value  # (with plans: the plans' ends)
        self.files: dict[str, str] = {}  # checkpoint file -> sha, of what this allocator loaded
        if variant == "match":
            self._init_match(checkpoint, view_checkpoint, taxi_view_checkpoint)
        elif variant == "ppo":
            self._init_ppo(checkpoint)
        else:
            self._init_paper(checkpoint)

    @classmethod
    def with_models(cls, match_model, view_model, **params) -> MagnnetAllocator:
        """The ``match`` variant around models in memory (training: DAgger plays the model
        it is fitting)."""
        alloc = cls(partial="match", **params)
        alloc.model, alloc.view_model, alloc.partial = match_model, view_model, "view"
        alloc.taxi_view_model = view_model  # the one model on every partial view
        alloc.files = {"(in memory)": "-"}
        return alloc

    # ------------------------------------------------------------------ loading
    def _use(self, path, kinds):
        model, size, sha = load_model(path, self.name, kinds)
        self.files[Path(path).name] = sha
        return model, size

    def _init_match(self, checkpoint, view_checkpoint, taxi_view_checkpoint=None) -> None:
        from allocators.magnnet import match, views

        self._match_mod, self._views_mod = match, views
        self.model, _ = self._use(checkpoint or _exists(shipped("match")), ("match",))
        self.view_model = self.taxi_view_model = None
        if self.partial == "view":
            if self.view_weights != "taxi":
                self.view_model, _ = self._use(view_checkpoint or _exists(shipped("view")),
                                               ("view",))
            if self.view_weights != "view":
                self.taxi_view_model, _ = self._use(
                    taxi_view_checkpoint or _exists(shipped("view_taxi")), ("view",))
            if self.view_model is None:  # "taxi": the taxi weights on every partial view
                self.view_model = self.taxi_view_model
            if self.taxi_view_model is None:  # "view": view.pt on every partial view
                self.taxi_view_model = self.view_model
        # warm-up: torch's first call of each kernel is slow; pay it here, not in a decision
        warm = np.array([[1.0, 2.0], [2.0, 1.0]])
        match.scores_of(self.model, warm, np.zeros(2, bool))
        for m in {id(v): v for v in (self.view_model, self.taxi_view_model)
                  if v is not None}.values():
            views.view_scores(m, warm, np.zeros(2, bool), np.array([0, 1]), np.ones(2, bool))

    def _init_ppo(self, checkpoint) -> None:
        from allocators.magnnet import attention

        self._attention = attention
        self.ppo_model, _ = self._use(checkpoint or _exists(shipped("ppo")), ("ppo",))
        p = _dummy(2)  # warm-up
        attention.decide(self.ppo_model, p.cost, np.ones(2, bool), np.ones(2, bool), p.comm,
                         np.array([False, True]), 0)

    def _init_paper(self, checkpoint) -> None:
        import torch

        self._torch = torch
        self.paper: dict[int, tuple] = {}
        if checkpoint is not None:
            model, size = self._use(checkpoint, (self.variant,))
            self.paper[model.n_agents] = (model, size)
        else:
            for n in shipped_sizes(self.variant):
                model, size = self._use(shipped(self.variant, n), (self.variant,))
                self.paper[n] = (model, size)
        if not self.paper:
            raise ValueError(f"no checkpoint of variant {self.variant!r} ships; train one "
                             f"with `dispatch train magnnet --variant {self.variant}`")
        self.team_sizes = tuple(sorted(self.paper))  # (N = M, static: see allocate)
        for model, size in self.paper.values():  # warm-up
            n = model.n_agents
            p = _dummy(n)
            with torch.no_grad():
                model(observe(p, np.arange(n), np.ones(n, bool), size))

    def describe(self) -> dict[str, str]:
        """What ran: ``model``, ``variant`` and ``checkpoint`` (``file@sha256[:16]`` of every
        file this allocator loaded, comma-separated); for ``match`` also the decision rule
        under limited range (``view_hops``, ``claims``) and how taxi-scale views are brought
        to the training range (``cost_scale``, ``candidates``)."""
        model = {"match": "magnnet-match" + ("+view" if self.partial == "view" else ""),
                 "paper": "magnnet-paper", "paper_nb": "magnnet-paper+nb",
                 "ppo": "magnnet-attention-ppo"}[self.variant]
        out = {"model": model, "variant": self.variant,
               "checkpoint": ",".join(f"{k}@{v}" for k, v in sorted(self.files.items()))}
        if self.value is not None:
            out.update(value=f"{Path(self.value.path).name}@{_sha(self.value.path)}",
                       value_weight=f"{self.value.weight:g}")
        if self.variant == "match":
            out.update(view_hops=str(self.view_hops), claims=str(self.claims),
                       cost_scale=str(self.cost_scale), candidates=str(self.candidates),
                       view_candidates=str(self.view_candidates),
                       view_weights=self.view_weights)
        return out

    # ------------------------------------------------------------------ deciding
    def claim_steps(self, problem: AllocationProblem) -> int:
        """Claim exchanges before each round's requests (``claims``), where some agent does
        not hear the whole fleet (on a complete graph every view is the same: none needed)."""
        if self.variant != "match" or problem.comm.all():
            return 0
        return self.claims

    def allocate(self, problem):
        """The decentralized decision (see the module doc). With ``value``, every agent decides
        on its own row of the value-adjusted costs (:class:`learning.value.ValueOption`, the
        same adjustment as ``hungarian``'s, plus the file's constant :attr:`~learning.value.
        ValueOption.offset` so that the models read non-negative costs), the conflict rule
        compares those, and the requests record the travel times."""
        if self.value is None:
            return self._allocate(problem)
        from learning.value import travel_costs

        return travel_costs(self._allocate(self.value.problem(problem, shift=True)), problem)

    def _allocate(self, problem):
        from dataclasses import replace

        self._plans, self._known, self._complete = {}, None, None
        self._two = self._two_done = self._flies_all = None
        sent = steps = 0
        if self.variant == "match" and self.view_hops > 2 and not problem.comm.all():
            self._known, sent = flood(problem, self.view_hops)
            steps = self.view_hops
            # an agent knows its view holds its whole component when no member it knows of
            # has a neighbour outside it (every member's neighbour list came with its costs)
            k = self._known.astype(np.float32)  # float32: exact counts, BLAS (see flood)
            outside = (k @ np.asarray(problem.comm, np.float32)) > 0
            self._complete = ~(outside & ~self._known).any(axis=1)
        try:
            alloc = super().allocate(problem)
        finally:
            self._known = self._complete = None
            self._two = self._two_done = self._flies_all = self._cached_for = None
        if steps:
            alloc = replace(alloc, messages=alloc.messages + sent, hops=alloc.hops + steps)
        return alloc

    def choose(self, problem: AllocationProblem, agents: np.ndarray, open_tasks: np.ndarray,
               round_: int) -> np.ndarray:
        if self.variant == "match":
            return self._choose_match(problem, agents, open_tasks, round_)
        if self.variant == "ppo":
            n = problem.cost.shape[0]
            deciding = np.zeros(n, bool)
            deciding[agents] = True
            req = self._attention.decide(self.ppo_model, problem.cost, deciding, open_tasks,
                                         problem.comm, self._flies_of(problem, np.arange(n)),
                                         round_)
            return req[agents]
        return self._choose_paper(problem, agents, open_tasks)

    def _costs(self, cost: np.ndarray, candidates: bool = True):
        """A view's costs as the model reads them, and the rows of its candidate agents (None:
        every row): in the units the models were trained in (``cost_scale``), each task's
        edges cut to its ``candidates`` cheapest agents (ties to the lower row)."""
        cost, finite, wide = self._rescaled(cost, self.candidates)
        k = (CANDIDATES if wide else 0) if self.candidates == "auto" else self.candidates
        if not candidates or k == 0 or cost.shape[0] <= k:
            return cost, None
        # each task's k cheapest agents (a stable sort: ties to the lower row)
        top = np.argsort(np.where(finite, cost, np.inf), axis=0, kind="stable")[:k]
        kept = np.zeros(cost.shape, bool)
        kept[top, np.arange(cost.shape[1])[None, :]] = True
        kept &= finite
        return np.where(kept, cost, np.inf), kept.any(axis=1)

    def _rescaled(self, cost: np.ndarray, cut) -> tuple[np.ndarray, np.ndarray, bool]:
        """``cost`` in the units the models were trained in (``cost_scale``), which entries
        are finite, and whether the view is out of the training range (median finite cost
        above :data:`TRAIN_MAX_S`: a city's taxis, minutes away; only looked at where
        ``cost_scale`` or the cut setting ``cut`` is ``"auto"``)."""
        finite = np.isfinite(cost)
        wide, median = False, 0.0
        if finite.any() and "auto" in (self.cost_scale, cut, self.view_weights):
            median = float(np.median(cost[finite]))
            wide = median > TRAIN_MAX_S
        if self.cost_scale == "auto":
            if wide:
                cost = cost * (TRAIN_MEDIAN_S / median)
        elif self.cost_scale != 1:
            cost = cost / self.cost_scale
        return cost, finite, wide

    def _view_costs(self, cost: np.ndarray, active: np.ndarray):
        """A partial view's costs as the view model reads them (``cost_scale``, as
        :meth:`_costs`), and the rows it keeps (None: every row). On a view out of the training
        range (``view_candidates = "auto"``: as :meth:`_costs` tells it; an integer: always)
        each task keeps the edges of its ``k`` cheapest deciding agents (ties to the lower row)
        and of the agents that stopped deciding and are no dearer than the dearest of those
        (they have most likely taken something: the model reads them as it was trained to);
        a row without a kept edge leaves the view, and an agent that leaves its own view
        requests nothing this round (as an agent that no task keeps under ``candidates``)."""
        cost, finite, wide = self._rescaled(cost, self.view_candidates)
        self._wide = wide  # which weights score it (view_weights = "auto")
        vc = self.view_candidates
        k = (CANDIDATES if wide else 0) if vc == "auto" else vc
        if k == 0 or cost.shape[0] <= k:
            return cost, None
        act = np.where(finite & active[:, None], cost, np.inf)
        top = np.argsort(act, axis=0, kind="stable")[:k]
        kept = np.zeros(cost.shape, bool)
        kept[top, np.arange(cost.shape[1])[None, :]] = True
        kept &= np.isfinite(act)
        dearest = np.where(kept, cost, -np.inf).max(axis=0)
        kept |= finite & ~active[:, None] & (cost <= dearest[None, :])
        rows = kept.any(axis=1)
        return np.where(kept, cost, np.inf)[rows], rows

    def _view_skips(self, cost: np.ndarray, agents: np.ndarray, two: np.ndarray,
                    deciding: np.ndarray) -> np.ndarray:
        """Per deciding agent (``agents``, with its two-hop rows ``two`` and the ``cost`` of
        every agent on this round's open tasks): True where :meth:`_view_costs` would cut the
        agent out of its own view (it requests nothing this round), found for all agents at
        once and without building their views. Exact: an agent is cut when its view is wide
        (median of its finite costs above :data:`TRAIN_MAX_S`; counted, and computed only
        where the two middle values straddle it) and on no task it is among the ``k``
        cheapest deciding agents of its view (ties to the lower index, as the stable sort).
        All False with ``view_candidates = 0`` (no cut)."""
        a = len(agents)
        vc = self.view_candidates
        if vc == 0 or a == 0:
            return np.zeros(a, bool)
        k = CANDIDATES if vc == "auto" else vc
        finite = np.isfinite(cost)
        if vc == "auto":
            two_f = two.astype(np.float32)
            t = two_f @ finite.sum(axis=1).astype(np.float32)
            g = two_f @ (finite & (cost > TRAIN_MAX_S)).sum(axis=1).astype(np.float32)
            odd = t % 2 == 1
            wide = np.where(odd, g >= (t + 1) / 2, g >= t / 2 + 1) & (t > 0)
            unsure = ~odd & (g == t / 2) & (t > 0)
            for r in np.flatnonzero(unsure):  # the two middle values straddle the bound
                v = cost[two[r]]
                wide[r] = float(np.median(v[np.isfinite(v)])) > TRAIN_MAX_S
        else:
            wide = np.ones(a, bool)
        # rank of each agent on each task among the deciding agents of its view
        act = deciding & finite.any(axis=1)
        cand = np.zeros(a, bool)
        idx = np.arange(len(cost))
        for j in range(cost.shape[1]):
            c = np.where(finite[:, j] & act, cost[:, j], np.inf)
            mine = cost[agents, j]
            before = (c[None, :] < mine[:, None]) | ((c[None, :] == mine[:, None])
                                                     & (idx[None, :] < agents[:, None]))
            rank = (before & two).sum(axis=1)
            cand |= np.isfinite(mine) & (rank < k)
        n_view = two.sum(axis=1)
        return wide & ~cand & (n_view > k)

    def _two_hop(self, comm: np.ndarray, rows: np.ndarray) -> np.ndarray:
        """``two[k]``: the agents within two hops of agent ``rows[k]`` (itself included), as
        :func:`allocators.magnnet.game.two_hop`; computed once per agent and decision, by
        float32 BLAS products (exact counts)."""
        n = len(comm)
        if self._two is None:
            self._two = np.zeros((n, n), bool)
            self._two_done = np.zeros(n, bool)
            self._comm_f = np.asarray(comm, np.float32).copy()
            np.fill_diagonal(self._comm_f, 1.0)
        todo = rows[~self._two_done[rows]]
        if todo.size:
            self._two[todo] = (self._comm_f[todo] @ self._comm_f) > 0
            self._two_done[todo] = True
        return self._two[rows]

    def _flies_of(self, problem, rows: np.ndarray) -> np.ndarray:
        """:meth:`_flies` of ``rows``, read once per decision for every agent."""
        if self._flies_all is None:
            self._flies_all = self._flies(problem, np.arange(problem.cost.shape[0]))
        return self._flies_all[rows]

    def _flies(self, problem, rows: np.ndarray) -> np.ndarray:
        """Whether the agents at ``rows`` fly. A run's vehicles (the dispatcher's lazy
        :class:`~dispatch.api.problem.AgentViews`) are read once per vehicle id: a vehicle
        keeps its kind, and views are built lazily (a thousand per decision is slow)."""
        if not problem.agents.lazy:  # views built already (hand-made): ids may be reused
            return np.array([problem.agents[r].flies for r in rows.tolist()], bool)
        known = self.__dict__.setdefault("_flies_by_id", {})
        ids = problem.agent_ids[rows].tolist()
        out = np.empty(len(ids), bool)
        for k, (r, a) in enumerate(zip(rows.tolist(), ids)):
            f = known.get(a)
            if f is None:
                f = known[a] = bool(problem.agents[r].flies)
            out[k] = f
        return out

    def _choose_paper(self, problem, agents, open_tasks) -> np.ndarray:
        n, m = problem.cost.shape
        if n != m or n not in self.paper:
            sizes = ", ".join(str(k) for k in sorted(self.paper))
            raise AllocationError(
                f"magnnet variant {self.variant!r}: no checkpoint for N={n} agents, M={m} "
                f"tasks (its checkpoints are for N = M in {{{sizes}}}); the default variant "
                "'match' serves any size")
        model, size = self.paper[n]
        obs = observe(problem, agents, open_tasks, size)
        with self._torch.no_grad():
            logits, _ = model(obs)
        act = logits[0].argmax(-1).numpy()[agents]
        return np.where(act > 0, act - 1, -1)

    def _choose_match(self, problem, agents, open_tasks, round_) -> np.ndarray:
        match, views = self._match_mod, self._views_mod
        if self.__dict__.get("_cached_for") is not problem:  # per-decision caches
            self._two = self._two_done = self._flies_all = None
            self._cached_for = problem
        comm = problem.comm
        deciding = np.zeros(problem.cost.shape[0], bool)
        deciding[agents] = True
        tasks = np.flatnonzero(open_tasks)
        out = np.full(len(agents), -1, np.int64)
        # an agent that hears every vehicle directly knows its view is everyone's
        hears_all = comm[agents].all(axis=1)
        late = round_ >= self.patience
        groups: dict[bytes, tuple[np.ndarray, list[int]]] = {}
        if hears_all.all():  # a complete graph: one view, every deciding agent
            members = np.flatnonzero(deciding)
            groups[members.tobytes()] = (members, list(range(len(agents))))
            agents_left = ()
        else:
            agents_left = enumerate(agents)
            two_rows = self._two_hop(comm, agents)
            if self.view_model is not None:
                skip = self._view_skips(problem.cost[:, tasks], agents, two_rows, deciding)
        pending = []  # the view model's views of this round, scored together below
        for k, i in agents_left:
            two = two_rows[k]
            if round_ == 0 and open_tasks.all() and self._complete is not None \
                    and self._complete[i]:
                # round 0: every agent that knows its whole component knows the same (all of
                # it, every task open) and computes the same plan; its part is its request
                comp = np.flatnonzero(self._known[i])
                key = comp.tobytes()
                if key not in self._plans:
                    cost, _ = self._costs(problem.cost[np.ix_(comp, tasks)], candidates=False)
                    self._plans[key] = match.plan(self.model, cost,
                                                  self._flies_of(problem, comp),
                                                  self.confidence)
                j = self._plans[key][int(np.searchsorted(comp, i))]
                out[k] = tasks[j] if j >= 0 else -2
                continue
            if hears_all[k] or self.view_model is None:
                members = np.flatnonzero(two & deciding)
                groups.setdefault(members.tobytes(), (members, []))[1].append(k)
                continue
            # the view model sees every agent within two hops, with whether it still decides:
            # one that no longer does and is the best for a task it believes open has most
            # likely taken it (the news may not have reached this agent yet)
            if skip[k]:
                continue  # cut out of its own view (as _view_costs would): nothing this round
            members = np.flatnonzero(two)
            hop, active = views.hops_from(comm, int(i), members), deciding[members]
            cost, rows = self._view_costs(problem.cost[np.ix_(members, tasks)], active)
            if rows is not None:  # a taxi-scale view: its candidates only (see _view_costs)
                if not rows[np.searchsorted(members, i)]:
                    continue  # not a candidate of its own view: nothing this round (-1)
                members, hop, active = members[rows], hop[rows], active[rows]
            if self._record is not None:  # DAgger: the view as the model reads it
                self._record.append((round_, members, tasks, hop, active, cost))
            taxi = self._wide if self.view_weights == "auto" else self.view_weights == "taxi"
            pending.append((k, i, members, active, taxi,
                            (cost, self._flies_of(problem, members), hop, active)))
        # every view of the round in one pass per model (the same numbers as one call per view,
        # up to the order of float sums: views.view_scores_many)
        scored: list = [None] * len(pending)
        for taxi, model in ((False, self.view_model), (True, self.taxi_view_model)):
            idx = [q for q, v in enumerate(pending) if v[4] == taxi]
            if idx:
                for q, res in zip(idx, views.view_scores_many(model, [pending[q][5]
                                                                      for q in idx])):
                    scored[q] = res
        for (k, i, members, active, _, _), (s, rn, cn) in zip(pending, scored):
            req = views.view_request(s, rn, cn, int(np.searchsorted(members, i)),
                                     self.view_confidence, force=round_ >= self.view_patience,
                                     active=active, last=round_ >= 2 * self.view_patience)
            out[k] = tasks[req] if req >= 0 else req
        # agents that share a view share one forward pass (one for everyone on a complete graph)
        for members, ks in groups.values():
            cost, keep = self._costs(problem.cost[np.ix_(members, tasks)])
            if keep is None:
                scores = match.scores_of(self.model, cost, self._flies_of(problem, members))
            else:  # candidates only (the others request nothing this round)
                scores = np.full(cost.shape, -np.inf)
                scores[keep] = match.scores_of(self.model, cost[keep],
                                                self._flies_of(problem, members[keep]))
            ks = np.asarray(ks)
            # waiting for confidence pays only where every agent shares one view (partial
            # views with partial = "match": requests regardless from round `patience` on)
            for full in (True, False):
                sel = ks[hears_all[ks] == full]
                if sel.size == 0:
                    continue
                req = match.mutual_best(scores, np.searchsorted(members, agents[sel]),
                                        force=late and not full,
                                        confidence=self.confidence if full else 0.0)
                out[sel] = np.where(req >= 0, tasks[np.maximum(req, 0)], -1)
        return out


def flood(problem: AllocationProblem, hops: int) -> tuple[np.ndarray, int]:
    """What ``hops`` synchronous flooding steps spread: ``known[i, j]``, agent ``i`` holds
    agent ``j``'s cost vector and neighbour list, and the broadcasts sent. In each step every
    agent with neighbours that learned something since its last broadcast sends one (all it
    knows); each reception is lost with ``problem.loss`` (drawn from ``problem.rng``)."""
    from dispatch.api.comms import Channel

    n = len(problem.comm)
    channel = Channel(problem.comm, problem.loss, problem.rng)
    has_nb = channel.has_neighbours()
    known = np.eye(n, dtype=bool)
    news = np.ones(n, bool)
    sent = 0
    for _ in range(hops):
        senders = np.flatnonzero(news & has_nb)
        if senders.size == 0:
            break
        got = channel.deliver(senders)
        sent += int(senders.size)
        # float32 counts are exact below 2^24 agents and go through BLAS (numpy's int64
        # product does not: about a second per decision at N = 500)
        new = known | ((got.T.astype(np.float32) @ known.astype(np.float32)) > 0)
        news = (new != known).any(axis=1)
        known = new
    return known, sent


def _exists(path: Path) -> Path:
    if not path.exists():
        raise ValueError(f"no checkpoint at {path}; train one with `dispatch train magnnet`")
    return path


def _dummy(n: int) -> AllocationProblem:
    from dispatch.api.problem import AgentView, TaskView

    agents = tuple(AgentView(i, "uav" if i % 2 else "ugv", (i, 0, 0), 3.0) for i in range(n))
    tasks = tuple(TaskView(j, "ground", (j, 1, 0), 0.0) for j in range(n))
    return AllocationProblem(0.0, agents, tasks, np.ones((n, n)), np.ones((n, n), bool),
                             np.random.default_rng(0))


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
