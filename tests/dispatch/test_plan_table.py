"""The fleet's plan and leg tables, read at a decision without a Python step per vehicle, hold
what the vehicles themselves say at that moment: every row a decision reads equals the
vehicle's own plan arrays (:meth:`dispatch.plan.vehicle_plan.Plan.arrays`) and load, and every
driving vehicle's place equals its leg's :meth:`dispatch.api.legs.Leg.next_at`. Checked at every
decision of pooled runs with service times, breakdowns (riders transferred) and re-routes."""

from __future__ import annotations

import numpy as np
import pytest

from dispatch.decide.plan_costs import PlanTable
from dispatch.plan.en_route import LegTable
from dispatch.run.runner import run_one
from dispatch.scenario.load import load_scenario
from tests.dispatch.test_trips import road_scenario, write_csv


def _trips(directory, rng, n: int) -> None:
    rows, t = [], 0.0
    for _ in range(n):
        t += float(rng.exponential(6.0))
        o, d = rng.choice(30, size=2, replace=False)
        # whole seconds: requests released at one instant, so a decision meets vehicles set
        # out at that instant that have not started their drive (standing, with a plan)
        rows.append((float(round(t)), int(o), int(d), int(rng.integers(1, 3))))
    write_csv(directory / "trips.csv", ["t", "origin_node", "dest_node", "passengers"], rows)


@pytest.mark.parametrize("faults", [False, True])
@pytest.mark.parametrize("service", [0.0, 15.0])
def test_the_tables_a_decision_reads_are_the_vehicles_own(tmp_path, monkeypatch, faults,
                                                          service):
    _trips(tmp_path, np.random.default_rng(int(faults) + 2 * int(service)), 120)
    extra = 'objective = "added_time"'
    if faults:
        extra += '\n\n[faults]\nrate = 3.0\nrepair = 120.0\non_board = "transfer"'
    path = road_scenario(tmp_path, tasks=f'source = "trace"\ntrace = "trips.csv"\n'
                         f'max_wait = 240.0\nmax_delay = 400.0\nservice_time = {service}',
                         fleet="agents = 6\ncapacity = 4", allocator="hungarian", extra=extra)
    checked = {"plans": 0, "legs": 0}
    gather, where = PlanTable.gather, LegTable.where

    def checked_gather(self, fleet, slots, now):
        out = gather(self, fleet, slots, now)
        off, arr, svc, lat, occ, locs, ear, load = out
        for i, k in enumerate(np.asarray(slots).tolist()):
            v = fleet.vehicles[k]
            times, svcs, latest, occs, where_, earliest = v.plan.arrays(now)  # asked afresh
            a, b = off[i], off[i + 1]
            assert arr[a:b].tolist() == times and svc[a:b].tolist() == svcs
            assert lat[a:b].tolist() == latest and occ[a:b].tolist() == occs
            assert ear[a:b].tolist() == earliest and list(locs[a:b]) == where_
            assert load[i] == v.load
            checked["plans"] += 1
        return out

    def checked_where(self, vehicles, idx, looked, node, rem, now, *, stands):
        points = where(self, vehicles, idx, looked, node, rem, now, stands=stands)
        for k in np.asarray(looked).tolist():
            v = vehicles[int(idx[k])]
            if v.leg is not None:
                want = v.leg.next_at(now - v.leg_start)
                assert (node[k], rem[k]) == want[:2]
                assert (k in points.tolist()) == (not want[2])
                checked["legs"] += 1
        return points

    monkeypatch.setattr(PlanTable, "gather", checked_gather)
    monkeypatch.setattr(LegTable, "where", checked_where)
    [spec] = load_scenario(path).runs()
    summary = run_one(spec).summary
    assert summary["tasks_completed"] > 60
    assert checked["plans"] > 200 and checked["legs"] > 200, checked
