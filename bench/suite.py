"""The bench suite: a fixed, versioned list of instances, each a shipped scenario with a few
settings changed, and its fixed seeds.

A new version of the suite (other instances, seeds or settings) gets a new :data:`VERSION`: a
board is comparable with another only when both name the same version. ``--quick`` runs the
instances marked ``quick``, on the first two of their seeds, each with its ``quick`` settings
(a shorter simulated time); its numbers are not the full suite's.
"""

from __future__ import annotations

import copy
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from bench import tomltext

#: The suite's version: every row of ``bench.md`` and the docs' board name it
VERSION = "bench-2026.1"
#: Where the shipped scenarios are (the suite's instances are made from them)
SCENARIOS = Path(__file__).resolve().parents[1] / "scenarios"
#: Baselines every instance runs besides the named allocators; ``rtv`` on pooled ones too
BASELINES = ("hungarian", "greedy")
POOLED_BASELINES = ("rtv",)
#: The reference of the paired differences (and, in static instances, the optimum)
REFERENCE = "hungarian"
QUICK_SEEDS = (0, 1)
GROUPS = ("robots", "fleets")
DELETE = object()  # an override that removes a key


@dataclass(frozen=True)
class Instance:
    """One problem of the suite: ``scenario`` (a file stem in ``scenarios/``, or None for
    ``base``, a document of its own), the settings changed (``overrides``, nested tables; a
    value :data:`DELETE` removes the key), its seeds, whether the quick suite has it and the
    settings the quick suite changes on top (``quick``)."""

    name: str
    group: str
    scenario: str | None
    overrides: dict = field(default_factory=dict)
    seeds: tuple[int, ...] = (0, 1, 2)
    in_quick: bool = False
    quick: dict = field(default_factory=dict)
    base: dict | None = None
    note: str = ""

    def document(self, quick: bool = False) -> dict:
        """The instance's scenario document (``[sweep]`` removed, its name ``bench_<name>``)."""
        if self.base is not None:
            doc = copy.deepcopy(self.base)
        else:
            doc = tomllib.loads(self.path.read_text(encoding="utf-8"))
        doc.pop("sweep", None)
        _merge(doc, self.overrides)
        if quick:
            _merge(doc, self.quick)
        doc["name"] = f"bench_{self.name}"
        if self.note:  # (the scenario's own description would name its settings, not ours)
            doc["description"] = f"{VERSION} {self.name}: {self.note}"
        return doc

    @property
    def path(self) -> Path:
        """The file relative paths in the document are read against."""
        return SCENARIOS / (f"{self.scenario}.toml" if self.scenario else f"bench_{self.name}.toml")

    def world(self) -> str:
        """``voxel`` or ``road``: the world the instance's vehicles move in."""
        return "road" if "network" in self.document().get("world", {}) else "voxel"

    def pooled(self) -> bool:
        """Whether vehicles take several requests at once (``rtv`` runs there)."""
        return int(self.document().get("fleet", {}).get("capacity", 1)) > 1

    def electric(self) -> bool:
        return "energy" in self.document().get("fleet", {})

    def baselines(self) -> tuple[str, ...]:
        return BASELINES + (POOLED_BASELINES if self.pooled() else ())

    def text(self, quick: bool = False, allocator: str | None = None,
             params: dict[str, Any] | None = None) -> str:
        """The scenario text of the instance; ``params`` go to ``allocator``'s own table
        ``[dispatch.allocator_params.<allocator>]`` (the other allocators' texts stay the same,
        so that their finished runs are reused)."""
        doc = self.document(quick)
        if params:
            tables = doc.setdefault("dispatch", {}).setdefault("allocator_params", {})
            tables.setdefault(allocator, {}).update(params)
        head = (f"# {VERSION}: instance {self.name}"
                + (f" (from scenarios/{self.scenario}.toml)" if self.scenario else "")
                + (" --quick" if quick else "") + "\n")
        return head + tomltext.dumps(doc)


def _merge(doc: dict, overrides: dict) -> None:
    for k, v in overrides.items():
        if v is DELETE:
            doc.pop(k, None)
        elif isinstance(v, dict):
            _merge(doc.setdefault(k, {}), v)
        else:
            doc[k] = copy.deepcopy(v)


def _grid_day(vehicles: int, requests: int, blocks: int) -> dict:
    """benchmarks/city_day.py's grid day at scale: a ``blocks`` x ``blocks`` Manhattan grid
    (200 m blocks, 10 m/s), Poisson requests uniform over the intersections for 24 h."""
    day = 86_400.0
    return {"seed": 0, "duration": day + 7200.0,
            "description": f"grid day: {blocks}x{blocks} blocks of 200 m, {vehicles} taxis, "
                           f"{requests} uniform Poisson requests over 24 h",
            "world": {"network": "manhattan", "blocks": [blocks, blocks], "block": 200.0,
                      "speed": 10.0},
            "fleet": {"agents": vehicles},
            "tasks": {"source": "poisson", "rate": requests / day, "count": requests,
                      "max_wait": 600.0},
            "dispatch": {"allocator": "hungarian", "planner": "dijkstra",
                         "batch_window": 30.0}}


_TEN = tuple(range(10))
_STATIC = [Instance(f"static_n{n}", "robots", "paper_static", {"fleet": {"agents": n}},
                    seeds=_TEN if n <= 20 else (0, 1, 2), in_quick=n in (4, 8, 20),
                    note=f"paper static, N = M = {n}")
           for n in (4, 8, 12, 20, 50, 100)]
_TWO_HOURS = {"duration": 7200.0}

#: The suite, in the order of the board
SUITE: tuple[Instance, ...] = (
    *_STATIC,
    Instance("dynamic_n8", "robots", "paper_dynamic", {"fleet": {"agents": 8}},
             in_quick=True, quick={"duration": 300.0},
             note="paper dynamic: Poisson 1/s, batched 5 s, ttl 60 s, N = 8, 600 s"),
    Instance("radio_20m", "robots", "comms_dynamic", {"fleet": {"agents": 8}},
             in_quick=True, quick={"duration": 300.0},
             note="radio range 20 m, 0.05 s/hop, 10 % loss, N = 8, 600 s"),
    Instance("radio_10m", "robots", "comms_dynamic",
             {"fleet": {"agents": 8}, "comms": {"range": 10.0}},
             in_quick=True, quick={"duration": 300.0},
             note="radio range 10 m, 0.05 s/hop, 10 % loss, N = 8, 600 s"),
    Instance("faults", "robots", "manhattan_faults", seeds=(0, 1, 2), in_quick=True,
             quick={"duration": 3600.0},
             note="grid taxis with breakdowns (0.2 per vehicle-hour, 10 min repairs, two for "
                  "good) and a 10-minute radio blackout, 9000 s"),
    Instance("chicago_n500_30s", "fleets", "chicago_taxi",
             {"fleet": {"agents": 500}, "dispatch": {"batch_window": 30.0}}, seeds=(0, 1),
             in_quick=True, quick=_TWO_HOURS,
             note="Chicago taxi day, 500 taxis, batched 30 s"),
    Instance("chicago_n1000_30s", "fleets", "chicago_taxi",
             {"fleet": {"agents": 1000}, "dispatch": {"batch_window": 30.0}}, seeds=(0, 1),
             note="Chicago taxi day, 1000 taxis, batched 30 s"),
    Instance("nyc_1seat", "fleets", "nyc_manhattan", seeds=(0, 1), in_quick=True,
             quick=_TWO_HOURS, note="Manhattan NYC day 2014-12-21, 700 taxis of 1 seat"),
    Instance("nyc_4seats", "fleets", "nyc_manhattan",
             {"fleet": {"agents": 300, "capacity": 4}, "tasks": {"max_delay": 600.0}},
             seeds=(0, 1), in_quick=True, quick={"duration": 3600.0},
             note="Manhattan NYC day, 300 taxis of 4 seats, drop-off delay <= 600 s"),
    # (its trace and its start file fix everything a seed draws: one seed is the instance)
    Instance("nyc_ev", "fleets", "nyc_manhattan_ev", seeds=(0,), in_quick=True,
             quick=_TWO_HOURS,
             note="Manhattan NYC day, 1200 electric taxis (HIVE), threshold charging"),
    Instance("grid_10k", "fleets", None, base=_grid_day(10_000, 400_000, 60), seeds=(0,),
             note="grid day at scale: 60x60 blocks, 10,000 taxis, 400,000 requests, 30 s"),
)


def instances(suite: str = "all", quick: bool = False) -> list[Instance]:
    """The instances of ``suite`` (``robots``, ``fleets`` or ``all``), of the quick suite if
    ``quick``."""
    if suite not in (*GROUPS, "all"):
        raise ValueError(f"--suite must be robots, fleets or all, got {suite!r}")
    return [i for i in SUITE if (suite == "all" or i.group == suite)
            and (i.in_quick or not quick)]


def seeds_of(instance: Instance, quick: bool = False, k: int | None = None) -> tuple[int, ...]:
    """The seeds an instance runs: its own (the quick suite: the first :data:`QUICK_SEEDS` of
    its own), or the first ``k`` (0, 1, … when ``k`` is more than it lists)."""
    own = instance.seeds[:len(QUICK_SEEDS)] if quick else instance.seeds
    if k is None:
        return own
    if k < 1:
        raise ValueError(f"--seeds must be >= 1, got {k}")
    return own[:k] if k <= len(own) else tuple(range(k))
