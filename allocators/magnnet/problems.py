"""Allocation instances for MAGNNET: drawn exactly as real runs draw them.

An instance of seed ``s`` and fleet size ``N`` is the first decision of the static scenario
(``scenarios/paper_static.toml`` by default) run with seed ``s``
(:func:`learning.instances.first_decision`: the world of the seed, the run's fleet and its
``M = N`` first tasks), costed with the exact A* travel times of the ``astar`` planner (found
through the registry: this package imports ``dispatch`` only). Training uses seeds from
:data:`TRAIN_SEED0` on; evaluation uses seeds from
:data:`EVAL_SEED0` on, so the two never overlap.

Computing A* costs takes seconds per instance (one distance field per task), so pools are built
once and cached as ``.npz`` files (see :func:`load_pool`).
"""

from __future__ import annotations

import logging
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

log = logging.getLogger(__name__)

TRAIN_SEED0 = 1_000_000
EVAL_SEED0 = 2_000_000
ROOT = Path(__file__).resolve().parents[2]
DEFAULT_SCENARIO = ROOT / "scenarios" / "paper_static.toml"


@dataclass
class Pool:
    """A stack of instances of one size: ``cost (B, N, M)`` seconds (``inf`` infeasible),
    ``agent_pos (B, N, 3)`` and ``task_pos (B, M, 3)`` in metres, ``flies (B, N)``,
    ``seeds (B,)``, and the world's size in metres (to normalize positions)."""

    cost: np.ndarray
    agent_pos: np.ndarray
    task_pos: np.ndarray
    flies: np.ndarray
    seeds: np.ndarray
    world_size: np.ndarray

    def __len__(self) -> int:
        return len(self.cost)

    def take(self, idx) -> Pool:
        return Pool(self.cost[idx], self.agent_pos[idx], self.task_pos[idx], self.flies[idx],
                    self.seeds[idx], self.world_size)


def instance(seed: int, n_agents: int, scenario: str | Path = DEFAULT_SCENARIO,
             n_tasks: int | None = None):
    """``(cost, agent_pos, task_pos, flies, world_size)`` of the first decision of one run."""
    from dispatch.api.registry import load
    from learning.instances import first_decision

    first = first_decision(scenario, seed, n_agents, n_tasks)
    world, agents, views = first.space, first.agents, first.tasks
    cost = load("planner", "astar")(world).costs(agents, views)
    grid = world.grid
    apos = np.array([grid.centre(a.cell) for a in agents], dtype=np.float32)
    tpos = np.array([grid.centre(t.cell) for t in views], dtype=np.float32)
    flies = np.array([a.flies for a in agents], dtype=bool)
    return cost, apos, tpos, flies, np.array(world.size, dtype=np.float32)


def build_pool(n_agents: int, count: int, seed0: int, scenario=DEFAULT_SCENARIO,
               workers: int = 1) -> Pool:
    """``count`` instances of seeds ``seed0, seed0 + 1, ...``."""
    seeds = list(range(seed0, seed0 + count))
    if workers > 1:
        from concurrent.futures import ProcessPoolExecutor

        with ProcessPoolExecutor(workers) as ex:
            rows = list(ex.map(instance, seeds, [n_agents] * count, [scenario] * count,
                               chunksize=max(1, count // (4 * workers))))
    else:
        rows = [instance(s, n_agents, scenario) for s in seeds]
    cost, apos, tpos, flies, size = zip(*rows)
    return Pool(np.stack(cost), np.stack(apos), np.stack(tpos), np.stack(flies),
                np.array(seeds, dtype=np.int64), size[0])


def cache_dir() -> Path:
    return Path(os.environ.get("MAGNNET_CACHE", ROOT / ".cache" / "magnnet"))


def _read(path: Path) -> Pool:
    z = np.load(path)
    return Pool(z["cost"], z["agent_pos"], z["task_pos"], z["flies"], z["seeds"],
                z["world_size"])


def load_pool(n_agents: int, count: int, split: str = "train", workers: int = 1) -> Pool:
    """A cached pool (``split`` ``"train"`` or ``"eval"``), built on first use."""
    seed0 = {"train": TRAIN_SEED0, "eval": EVAL_SEED0}[split]
    path = cache_dir() / f"{split}_n{n_agents}_c{count}.npz"
    if not path.exists():  # a bigger cached pool holds the same seeds first
        bigger = sorted((int(q.stem.rsplit("_c", 1)[1]), q)
                        for q in cache_dir().glob(f"{split}_n{n_agents}_c*.npz")
                        if q.stem.rsplit("_c", 1)[1].isdigit()
                        and int(q.stem.rsplit("_c", 1)[1]) > count)
        if bigger:
            return _read(bigger[0][1]).take(slice(0, count))
    if path.exists():
        return _read(path)
    log.info("building %s pool: %d instances of N=%d", split, count, n_agents)
    pool = build_pool(n_agents, count, seed0, workers=workers)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_suffix(".tmp.npz")
    np.savez_compressed(tmp, cost=pool.cost, agent_pos=pool.agent_pos, task_pos=pool.task_pos,
                        flies=pool.flies, seeds=pool.seeds, world_size=pool.world_size)
    tmp.replace(path)
    return pool
