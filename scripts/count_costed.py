"""How many vehicles' costs a run's one-request decisions compute, with the exact vehicle cut
(:mod:`dispatch.decide.nearest`, engaged at every fleet size) and with the whole column; and
whether the two runs' tables are the same. Counts, not times: each call of the planner for one
request adds the vehicles it is asked about.

Run: ``PYTHONPATH=. .venv/bin/python scripts/count_costed.py chicago_taxi.toml --agents 1000
--duration 93600 --allocator fcfs --out /tmp/counted`` (the run is the scenario's first of
that allocator and fleet size, decided at once: ``batch_window = 0``).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from dispatch.decide import nearest, planner_costs  # noqa: E402
from dispatch.run.runner import execute  # noqa: E402
from dispatch.scenario.load import load_scenario  # noqa: E402
from tests.dispatch.test_determinism import read_run  # noqa: E402
from tests.dispatch.test_one_request import assert_same_tables  # noqa: E402


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("scenario", help="a file of scenarios/")
    ap.add_argument("--agents", type=int, required=True)
    ap.add_argument("--duration", default="3600")
    ap.add_argument("--allocator", default="fcfs")
    ap.add_argument("--out", type=Path, required=True)
    args = ap.parse_args()
    counted = {"vehicles": 0, "calls": 0}
    real = planner_costs.PlannerCosts.__call__

    def counting(self, agents, tasks):
        if len(tasks) == 1:
            counted["vehicles"] += len(agents)
            counted["calls"] += 1
        return real(self, agents, tasks)

    planner_costs.PlannerCosts.__call__ = counting
    nearest.MIN_CANDIDATES = 0
    tables = {}
    for full in (True, False):
        nearest.FULL = full
        counted.update(vehicles=0, calls=0)
        sc = load_scenario(ROOT / "scenarios" / args.scenario, force=True,
                           overrides=[("duration", args.duration, "--duration")])
        spec = sc.runs(allocator=args.allocator, agents=args.agents, batch_window=0.0)[0]
        out = args.out / ("whole" if full else "cut")
        execute([spec], out)
        tables[full] = read_run(out)
        dec = tables[full]["decisions"]
        built = counted["calls"]
        print(f"{'whole column' if full else 'exact cut'}: {counted['vehicles']:,} vehicles "
              f"costed in {built:,} one-request costings; {dec.num_rows:,} decisions recorded; "
              f"idle vehicles a decision {np.mean(dec.column('n_idle').to_numpy()):.1f}",
              flush=True)
    assert_same_tables(tables[True], tables[False])
    print("tables: all the same")


if __name__ == "__main__":
    main()
