"""The ``demand`` repositioner on hand-built views: zones, shares and moves computed by hand,
and its assignment checked against brute force over every admissible choice of vehicles."""

from __future__ import annotations

import itertools

import numpy as np
import pytest
from scipy.sparse.csgraph import dijkstra

from dispatch.api.legs import RoadPoint
from dispatch.checks.repositioners import check_repositioner, reposition_view
from dispatch.space.roads import manhattan
from repositioners.demand import DemandRepositioner, shares
from repositioners.stay import StayRepositioner
from learning.zones import Zones

#: 6 x 2 intersections, 200 m blocks at 10 m/s (20 s an edge): node row * 6 + column at
#: (200 column, 200 row). With 600 m zones, columns 0-2 are zone 0 and columns 3-5 zone 1.
NET = manhattan(6, 2, 200.0, 10.0)


def test_grid_zones_by_hand():
    z = Zones(NET.xy, 600.0)
    assert z.n == 2
    assert z.of_node.tolist() == [0, 0, 0, 1, 1, 1, 0, 0, 0, 1, 1, 1]
    # zone 0's nodes average (200, 100): nodes 1 (200, 0) and 7 (200, 200) tie, the lower wins
    assert z.centre_nodes.tolist() == [1, 4]
    one = Zones(NET.xy, 5000.0)
    assert one.n == 1 and set(one.of_node.tolist()) == {0}
    # 200 m zones: every column of each row... x and y both split: 12 zones, one node each
    fine = Zones(NET.xy, 200.0)
    assert fine.n == 12 and sorted(fine.centre_nodes.tolist()) == list(range(12))


@pytest.mark.parametrize("total, weights, want", [
    (5, [1, 1, 1], [2, 2, 1]), (1, [0, 3], [0, 1]), (3, [1, 2], [1, 2]),
    (4, [1, 0, 0, 1], [2, 0, 0, 2]), (0, [2, 5], [0, 0]), (7, [1, 1], [4, 3]),
])
def test_shares_by_hand(total, weights, want):
    assert shares(total, np.array(weights, float)).tolist() == want


def test_shares_sum_and_stay_within_one_of_the_quota():
    g = np.random.default_rng(1)
    for _ in range(200):
        w = g.integers(0, 6, g.integers(1, 8)).astype(float)
        if w.sum() == 0:
            continue
        total = int(g.integers(0, 30))
        out = shares(total, w)
        quota = total * w / w.sum()
        assert out.sum() == total and (np.abs(out - quota) < 1).all() and (out >= 0).all()


def test_a_vehicle_in_a_zone_without_demand_goes_to_the_zone_with_demand():
    view = reposition_view(NET, {7: 0}, [(10.0, 10), (20.0, 10), (30.0, 3)], time=100.0)
    assert DemandRepositioner(zone=600.0).reposition(view) == {7: 4}


def test_no_demand_or_balanced_supply_moves_nobody():
    rep = DemandRepositioner(zone=600.0)
    assert rep.reposition(reposition_view(NET, {1: 0, 2: 3}, [])) == {}
    # one request in each zone, one vehicle in each: balanced
    assert rep.reposition(reposition_view(NET, {1: 0, 2: 3}, [(0.0, 2), (1.0, 9)])) == {}
    # the only vehicle already drives to the zone with the demand: it is counted there
    assert rep.reposition(reposition_view(NET, {5: 0}, [(0.0, 10)], targets={5: 4})) == {}


def test_the_nearest_surplus_vehicles_fill_the_deficit():
    # 3 vehicles in zone 0 (nodes 0, 2, 8), 1 in zone 1; demand 1 in zone 0, 3 in zone 1:
    # shares 4 * (1/4, 3/4) = (1, 3): zone 0 gives 2, zone 1 needs 2. To node 4 (zone 1's
    # centre): from node 2 two edges (40 s), from 8 three (60 s), from 0 four (80 s).
    view = reposition_view(NET, {10: 0, 11: 2, 12: 8, 13: 9},
                           [(0.0, 1), (1.0, 10), (2.0, 10), (3.0, 11)])
    assert DemandRepositioner(zone=600.0).reposition(view) == {11: 4, 12: 4}
    assert DemandRepositioner(zone=600.0, max_moves=1).reposition(view) == {11: 4}


def test_travel_times_start_part_way_along_an_edge():
    # a vehicle 5 s before node 2 on the edge 1 -> 2: to node 4 is 5 + 40 s
    view = reposition_view(NET, {3: RoadPoint(2, 1, 5.0, 50.0), 4: 0}, [])
    t = view.travel_times(np.array([0, 1]), np.array([4, 0]))
    assert t.tolist() == [[45.0, 45.0], [80.0, 0.0]]


def _brute_force(view, zones, surplus, slots):
    """Least total travel time over every choice of distinct standing vehicles for the slots
    that takes at most surplus[z] from each zone z (an independent enumeration)."""
    times = dijkstra(NET.time)  # all pairs, seconds
    still = [i for i in range(view.n_vehicles) if view.targets[i] < 0]
    zone = {i: zones.of_node[view.nodes[i]] for i in still}
    best = np.inf
    for chosen in itertools.permutations(still, len(slots)):
        counts = np.bincount([zone[i] for i in chosen], minlength=zones.n)
        if (counts > surplus).any():
            continue
        best = min(best, sum(times[view.nodes[i], zones.centre_nodes[z]]
                             for i, z in zip(chosen, slots)))
    return best


def test_the_assignment_is_the_cheapest_admissible_one_brute_force():
    rep = DemandRepositioner(zone=400.0, max_moves=3)  # zones of 2 x 2 nodes: 3 x 1 zones
    zones = rep.zones(NET)
    times = dijkstra(NET.time)
    g = np.random.default_rng(5)
    checked = 0
    for trial in range(60):
        nv = int(g.integers(1, 7))
        vehicles = {100 + i: int(n) for i, n in enumerate(g.integers(0, NET.n, nv))}
        req = [(float(i), int(n)) for i, n in enumerate(g.integers(0, NET.n, g.integers(1, 8)))]
        view = reposition_view(NET, vehicles, req)
        moves = rep.reposition(view)
        demand = np.bincount(zones.of_node[[n for _, n in req]], minlength=zones.n)
        supply = np.bincount(zones.of_node[view.nodes], minlength=zones.n)
        share = shares(nv, demand.astype(float))
        surplus = np.maximum(supply - share, 0)
        deficit = np.maximum(share - supply, 0)
        k = int(min(surplus.sum(), deficit.sum(), 3))
        assert len(moves) == k
        # the slots are the k largest gaps; which zones they are is fixed, so the brute force
        # enumerates the vehicles for the same slots
        slots = sorted(zones.of_node[list(moves.values())].tolist())
        gaps = sorted(((deficit[z] - j, -z) for z in range(zones.n)
                       for j in range(deficit[z])), reverse=True)[:k]
        assert slots == sorted(-z for _, z in gaps)
        got = sum(times[vehicles[v], node] for v, node in moves.items())
        assert got == pytest.approx(_brute_force(view, zones, surplus, slots)), trial
        checked += k > 0
    assert checked > 10


def test_bad_parameters_are_one_line_errors():
    for kwargs, words in (({"zone": 0}, "zone must be"), ({"zone": "big"}, "zone must be"),
                          ({"max_moves": 0}, "max_moves must be"),
                          ({"max_moves": 2.5}, "max_moves must be")):
        with pytest.raises(ValueError, match=words):
            DemandRepositioner(**kwargs)
    with pytest.raises(TypeError):
        DemandRepositioner(radius=3)


@pytest.mark.parametrize("cls, params", [(DemandRepositioner, {}),
                                         (DemandRepositioner, {"zone": 150.0, "max_moves": 3}),
                                         (StayRepositioner, {})])
def test_the_shipped_repositioners_pass_the_plugin_checks(cls, params):
    report = check_repositioner(cls, **params)
    assert report.ok, str(report)
