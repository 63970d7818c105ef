"""Benchmark: the cheapest feasible insertion (``dispatch.plan.insertion.insertion_costs``) against
the
exhaustive search that re-simulates every plan
(``tests.dispatch.reference.brute_force_insertion``, the reference the tests hold it to), on
the same random pairs, in the same run.

Pairs: a vehicle whose plan holds ``--stops`` stops (requests picked up or waiting, capacity 4,
limits with random slack, travel times of points in the plane) and a new request. Both sides
get the same travel times; the reference reads them from a dict, ours from the stop x request
matrices the dispatcher gathers. Printed per plan length: pairs per second of each, the ratio,
and the share of pairs the pickup-deadline bound (a vehicle that cannot reach the pickup in
time by the direct drive, the dispatcher's prune before any stop is looked at) removes.

Run: ``.venv/bin/python benchmarks/insertion.py [--pairs 20000] [--stops 0 2 4 6 8]``.
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from dispatch.plan.insertion import insertion_costs  # noqa: E402
from dispatch.plan.stops import ADDED_TIME  # noqa: E402
from tests.dispatch.reference import brute_force_insertion  # noqa: E402

#: pairs per simulated decision
BATCH = 500


def make(rng: np.random.Generator, pairs: int, k: int):
    """``pairs`` random (vehicle, request) cases with plans of ``k`` stops, as flat arrays."""
    pts = rng.uniform(0, 4000, size=(pairs, k + 3, 2))  # vehicle, k stops, pickup, drop-off
    tt = np.hypot(*(pts[:, :, None, :] - pts[:, None, :, :]).transpose(3, 0, 1, 2)) / 10.0
    cap = 4
    cases = []
    for q in range(pairs):
        # a plan of k/2 requests: pickups then drop-offs in order (occupancy <= k/2 <= cap)
        half = k // 2
        pax = [1] * half + [-1] * half + ([-1] if k % 2 else [])
        load = 1 if k % 2 else 0
        t, arr = 0.0, []
        for m in range(k):
            t += tt[q, m, m + 1]
            arr.append(t)
        latest = [a + rng.uniform(100, 600) for a in arr]
        cases.append((arr, pax, latest, load, cap))
    return tt, cases


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--pairs", type=int, default=20000)
    p.add_argument("--stops", type=int, nargs="+", default=[0, 2, 4, 6, 8])
    p.add_argument("--seed", type=int, default=0)
    a = p.parse_args(argv)
    rng = np.random.default_rng(a.seed)
    print(f"{'stops':>5} {'ours pairs/s':>13} {'reference':>10} {'ratio':>7} {'pruned':>7} "
          f"{'agree':>11}")
    for k in a.stops:
        tt, cases = make(rng, a.pairs, k)
        n = a.pairs
        lp = np.array([rng.uniform(60, 600) for _ in range(n)])
        ld = lp + tt[:, k + 1, k + 2] + 600.0
        first = tt[:, 0, k + 1]
        pruned = float((first > lp).mean())
        # ours: flat arrays, one vehicle and one request per pair, in decisions of ``BATCH``
        # pairs (the stop x request matrices of a decision are dense)
        cost = np.empty(n)
        t_ours = 0.0
        for lo in range(0, n, BATCH):
            hi = min(n, lo + BATCH)
            b = hi - lo
            part = cases[lo:hi]
            off = np.arange(0, (b + 1) * k, k) if k else np.zeros(b + 1, np.int64)
            s_arr = np.concatenate([c[0] for c in part]) if k else np.zeros(0)
            s_lat = np.concatenate([c[2] for c in part]) if k else np.zeros(0)
            s_occ = (np.concatenate([np.cumsum(c[1]) + c[3] for c in part]) if k
                     else np.zeros(0, np.int64))
            g = b * k
            to_p, from_p = np.zeros((g, b)), np.zeros((b, g))
            to_d, from_d = np.zeros((g, b)), np.zeros((b, g))
            for q in range(b):
                for m in range(k):
                    to_p[q * k + m, q] = tt[lo + q, m + 1, k + 1]
                    from_p[q, q * k + m] = tt[lo + q, k + 1, m + 1]
                    to_d[q * k + m, q] = tt[lo + q, m + 1, k + 2]
                    from_d[q, q * k + m] = tt[lo + q, k + 2, m + 1]
            rows, cols = np.arange(b), np.arange(b)
            kw = dict(ready=np.zeros(b), first_tt=first[lo:hi], off=off, s_arr=s_arr,
                      s_svc=np.zeros(g), s_latest=s_lat, s_occ=s_occ,
                      load=[c[3] for c in part], cap=np.full(b, 4), to_p=to_p, from_p=from_p,
                      to_d=to_d, from_d=from_d, pd_tt=tt[lo:hi, k + 1, k + 2],
                      req_n=np.ones(b, np.int64), req_lp=lp[lo:hi], req_ld=ld[lo:hi],
                      req_svc_p=np.zeros(b), req_svc_d=np.zeros(b), objective=ADDED_TIME)
            if lo == 0:
                insertion_costs(rows, cols, **kw)  # compiled on the first call: not timed
            t0 = time.perf_counter()
            cost[lo:hi] = insertion_costs(rows, cols, **kw).cost
            t_ours += time.perf_counter() - t0
        sample = min(n, 2000)
        t0 = time.perf_counter()
        agree = 0
        for q in range(sample):
            arr, pax, latest, load, cap = cases[q]
            stops = [(m + 1, pax[m], latest[m], 0.0) for m in range(k)]
            want = brute_force_insertion(
                0.0, lambda loc, q=q: tt[q, 0, loc], stops, load, cap,
                (k + 1, k + 2, 1, lp[q], ld[q], 0.0, 0.0),
                lambda x, y, q=q: tt[q, x, y], ADDED_TIME)
            same = (math.isinf(want[0]) and math.isinf(cost[q])) or \
                abs(want[0] - cost[q]) < 1e-6
            agree += same
        t_ref = (time.perf_counter() - t0) * n / sample
        print(f"{k:>5} {n / t_ours:>13,.0f} {n / t_ref:>10,.0f} {t_ref / t_ours:>6.0f}x "
              f"{100 * pruned:>6.1f}% {agree}/{sample}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
