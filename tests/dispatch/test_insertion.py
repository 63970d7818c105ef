"""The compiled cheapest insertion (dispatch.plan.insertion.insertion_costs) against an exhaustive
search
that re-simulates every plan (tests.dispatch.reference.brute_force_insertion), on random stop
lists of up to 6 stops, random capacities, limits and travel times (a metric: points in the
plane)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from dispatch.plan.insertion import insertion_costs
from dispatch.plan.stops import ADDED_TIME, PICKUP_TIME
from tests.dispatch.reference import brute_force_insertion


def _case(rng: np.random.Generator):
    """A random feasible plan and a batch of requests: ``(vehicle, stops, requests, tt)``."""
    pts = rng.uniform(0, 1000, size=(40, 2))

    def tt(a: int, b: int) -> float:
        return float(np.hypot(*(pts[a] - pts[b]))) / 10.0

    cap = int(rng.integers(1, 7))
    svc = float(rng.choice([0.0, 0.0, 15.0]))
    here = 0
    ready = float(rng.uniform(0, 50))
    # a plan of up to 3 requests (6 stops) built by appending pickups and drop-offs in a
    # random interleaving that never exceeds the capacity
    n_req = int(rng.integers(0, 4))
    pending, load0, on_board = [], 0, []
    loc = 1
    for _ in range(n_req):
        n = int(rng.integers(1, cap + 1))
        pending.append((loc, loc + 1, n))
        loc += 2
    # some requests already on board (their pickup done): only their drop-off is in the plan
    events = []
    for p, d, n in pending:
        if rng.random() < 0.3 and load0 + n <= cap:
            load0 += n
            on_board.append((d, n))
        else:
            events.append((p, d, n))
    seq = [("d", d, n) for d, n in on_board]
    for p, d, n in events:
        seq.append(("p", p, n))
        seq.append(("d", d, n))
    rng.shuffle(seq)
    # fix the order: a pickup before its drop-off; drop capacity violations by re-ordering
    order, occ, waiting = [], load0, list(seq)
    picked = set()
    while waiting:
        for k, (kind, where, n) in enumerate(waiting):
            if kind == "p" and occ + n <= cap:
                occ += n
                picked.add(where + 1)
                order.append((where, n, svc * 0))
                waiting.pop(k)
                break
            if kind == "d" and (where in picked or (where, n) in on_board):
                occ -= n
                order.append((where, -n, svc))
                waiting.pop(k)
                break
        else:  # nothing fits (cannot happen with n <= cap): give up on this case
            return None
    # schedule, then latest times with random slack (feasible by construction)
    t, prev, arr = ready, None, []
    for where, n, s in order:
        t += tt(here if prev is None else prev, where)
        arr.append(t)
        t += s
        prev = where
    stops = [(where, n, a + float(rng.choice([0.0, rng.uniform(0, 300), math.inf])), s)
             for (where, n, s), a in zip(order, arr)]
    reqs = []
    for r in range(5):
        p, d = int(rng.integers(20, 40)), int(rng.integers(20, 40))
        n = int(rng.integers(1, cap + 2))
        lp = ready + float(rng.uniform(0, 400))
        ld = lp + tt(p, d) + float(rng.choice([rng.uniform(0, 400), math.inf]))
        reqs.append((p, d, n, lp, ld, 0.0, svc))
    return dict(ready=ready, here=here, stops=stops, arr=arr, load=load0, cap=cap,
                reqs=reqs, tt=tt)


def _compiled(c, objective):
    stops, reqs, tt = c["stops"], c["reqs"], c["tt"]
    k, m = len(stops), len(reqs)
    g_loc = [s[0] for s in stops]
    to_p = np.array([[tt(g, r[0]) for r in reqs] for g in g_loc]).reshape(k, m)
    from_p = np.array([[tt(r[0], g) for g in g_loc] for r in reqs]).reshape(m, k)
    to_d = np.array([[tt(g, r[1]) for r in reqs] for g in g_loc]).reshape(k, m)
    from_d = np.array([[tt(r[1], g) for g in g_loc] for r in reqs]).reshape(m, k)
    occ, s_occ = c["load"], []
    for s in stops:
        occ += s[1]
        s_occ.append(occ)
    return insertion_costs(
        np.zeros(m, np.int64), np.arange(m), ready=[c["ready"]],
        first_tt=[tt(c["here"], r[0]) for r in reqs], off=[0, k], s_arr=c["arr"],
        s_svc=[s[3] for s in stops], s_latest=[s[2] for s in stops], s_occ=s_occ,
        load=[c["load"]], cap=[c["cap"]], to_p=to_p, from_p=from_p, to_d=to_d, from_d=from_d,
        pd_tt=[tt(r[0], r[1]) for r in reqs], req_n=[r[2] for r in reqs],
        req_lp=[r[3] for r in reqs], req_ld=[r[4] for r in reqs],
        req_svc_p=[r[5] for r in reqs], req_svc_d=[r[6] for r in reqs], objective=objective)


@pytest.mark.parametrize("objective", [PICKUP_TIME, ADDED_TIME])
def test_insertion_equals_exhaustive_search(objective):
    rng = np.random.default_rng(7 + objective)
    cases = feasible = 0
    while cases < 300:
        c = _case(rng)
        if c is None:
            continue
        cases += 1
        got = _compiled(c, objective)
        tt, here = c["tt"], c["here"]
        for q, req in enumerate(c["reqs"]):
            want = brute_force_insertion(c["ready"], lambda loc: tt(here, loc), c["stops"],
                                         c["load"], c["cap"], req, tt, objective)
            if math.isinf(want[0]):
                assert math.isinf(got.cost[q]), (q, want, got.of(q))
                continue
            feasible += 1
            assert got.cost[q] == pytest.approx(want[0], abs=1e-6), (want, got.of(q))
            assert got.pickup_at[q] == pytest.approx(want[3], abs=1e-6)
    assert feasible > 200  # the cases exercise both outcomes


def test_shifts_match_the_new_schedule():
    """``shift1``/``shift2`` and the drop-off time are those of the re-simulated new plan."""
    rng = np.random.default_rng(3)
    checked = 0
    while checked < 100:
        c = _case(rng)
        if c is None or not c["stops"]:
            continue
        got = _compiled(c, ADDED_TIME)
        tt, here = c["tt"], c["here"]
        for q, (p, d, n, lp, ld, sp, sd) in enumerate(c["reqs"]):
            if math.isinf(got.cost[q]):
                continue
            i, j, pick, drop, s1, s2, _ = got.of(q)  # (no meeting points here)
            plan = list(c["stops"])
            plan.insert(j, (d, -n, ld, sd))
            plan.insert(i, (p, n, lp, sp))
            t, prev, arr = c["ready"], None, []
            for where, _, _, s in plan:
                t += tt(here if prev is None else prev, where)
                arr.append(t)
                t += s
                prev = where
            assert arr[i] == pytest.approx(pick, abs=1e-6)
            assert arr[j + 1] == pytest.approx(drop, abs=1e-6)
            old = c["arr"]
            for m in range(len(old)):  # old stop m sits at m, m + 1 or m + 2 in the new plan
                pos = m + (m >= i) + (m >= j)
                shift = 0.0 if m < i else (s1 if m < j else s2)
                assert arr[pos] == pytest.approx(old[m] + shift, abs=1e-6)
            checked += 1
