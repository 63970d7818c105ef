"""The compiled set-up of a decision's insertions (dispatch.plan.insertion.candidate_pairs)
against the same set-up written with numpy array operations, on random decisions: the empty
plans' costs bit for bit, the busy vehicles' candidate pairs in the same order, with the same
ready times, seats and drives."""

from __future__ import annotations

import numpy as np
import pytest

from dispatch.plan.insertion import candidate_pairs


def numpy_setup(cost, now, slots, planned, cap, free_at, lp, ld, n_req, ep, svc_p, svc_d, pd,
                pickup_time):
    """The set-up by whole-array operations: ``(out, rows, cols, used, ready, seats,
    ucols)``."""
    out = np.full(cost.shape, np.inf)
    empty = np.flatnonzero(~planned)
    c = cost[empty]
    arr_p = now + c
    arr_d = np.maximum(arr_p, ep) + svc_p + pd
    ok = (arr_p <= lp + 1e-9) & (arr_d <= ld + 1e-9) & (n_req <= cap[slots[empty], None])
    value = c if pickup_time else c + svc_p + pd + svc_d
    out[empty] = np.where(ok, value, np.inf)
    busy = np.flatnonzero(planned)
    ready = np.maximum(free_at[slots[busy]], now)
    r, cols = ((ready[:, None] + cost[busy] <= lp + 1e-9)
               & (n_req <= cap[slots[busy], None])).nonzero()
    used = np.unique(r)
    return (out, busy[r], cols, busy[used], ready[used], cap[slots[busy[used]]],
            np.unique(cols))


def random_decision(rng, n, m, fleet):
    slots = np.sort(rng.choice(fleet, n, replace=False))
    cost = rng.uniform(0.0, 900.0, (n, m))
    cost[rng.random((n, m)) < 0.1] = np.inf
    now = float(rng.uniform(0, 5000))
    planned = rng.random(n) < 0.6
    cap = rng.integers(1, 5, fleet)
    free_at = np.where(rng.random(fleet) < 0.5, -np.inf, now + rng.uniform(-300, 300, fleet))
    lp = now + rng.uniform(-100, 900, m)
    ld = lp + rng.uniform(0, 1500, m)
    ld[rng.random(m) < 0.2] = np.inf
    n_req = rng.integers(0, 4, m)
    ep = np.where(rng.random(m) < 0.7, -np.inf, now + rng.uniform(-200, 600, m))
    point = rng.random(m) < 0.2
    svc = float(rng.choice([0.0, 30.0]))
    svc_p, svc_d = np.where(point, svc, 0.0), np.where(point, 0.0, svc)
    pd = np.where(point, 0.0, rng.uniform(60, 900, m))
    return {"cost": cost, "now": now, "slots": slots, "planned": planned, "cap": cap,
            "free_at": free_at, "lp": lp, "ld": ld, "n_req": n_req, "ep": ep, "svc_p": svc_p,
            "svc_d": svc_d, "pd": pd}


@pytest.mark.parametrize("seed", range(40))
@pytest.mark.parametrize("pickup_time", [True, False])
def test_compiled_setup_is_the_array_setup(seed, pickup_time):
    rng = np.random.default_rng([seed, 39])
    n, m = int(rng.integers(1, 40)), int(rng.integers(1, 6))
    d = random_decision(rng, n, m, fleet=60)
    want = numpy_setup(**d, pickup_time=pickup_time)
    out = np.full(d["cost"].shape, np.inf)
    rows, cols, row_of, used, ready, seats, ucols, pcol, first_tt = candidate_pairs(
        d["cost"], d["now"], d["slots"], d["planned"], cap=d["cap"], free_at=d["free_at"],
        lp=d["lp"], ld=d["ld"], n_req=d["n_req"], ep=d["ep"], svc_p=d["svc_p"],
        svc_d=d["svc_d"], pd=d["pd"], pickup_time=pickup_time, out=out)
    w_out, w_rows, w_cols, w_used, w_ready, w_seats, w_ucols = want
    np.testing.assert_array_equal(out, w_out)  # (exact: the same doubles, inf where inf)
    assert rows.tolist() == w_rows.tolist() and cols.tolist() == w_cols.tolist()
    assert used.tolist() == w_used.tolist() and seats.tolist() == w_seats.tolist()
    assert ready.tolist() == w_ready.tolist()
    assert ucols.tolist() == w_ucols.tolist()
    # each pair names its vehicle among ``used``, its column among ``ucols``, and its drive
    assert used[row_of].tolist() == rows.tolist()
    assert ucols[pcol].tolist() == cols.tolist()
    assert first_tt.tolist() == d["cost"][rows, cols].tolist()


def test_no_pairs_without_busy_vehicles():
    rng = np.random.default_rng(5)
    d = random_decision(rng, 10, 3, fleet=20)
    d["planned"][:] = False
    out = np.full(d["cost"].shape, np.inf)
    got = candidate_pairs(d["cost"], d["now"], d["slots"], d["planned"], cap=d["cap"],
                          free_at=d["free_at"], lp=d["lp"], ld=d["ld"], n_req=d["n_req"],
                          ep=d["ep"], svc_p=d["svc_p"], svc_d=d["svc_d"], pd=d["pd"],
                          pickup_time=False, out=out)
    assert all(a.size == 0 for a in got)
    np.testing.assert_array_equal(out, numpy_setup(**d, pickup_time=False)[0])
