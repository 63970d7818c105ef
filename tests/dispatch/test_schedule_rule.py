"""The one schedule rule (dispatch.plan.stops) against an independent brute force
(tests/dispatch/reference.py) over every order of small plans holding every stop kind: pickups
and drop-offs among charge, reposition, depot and break stops, with earliest and latest times,
capacities and service times (random small instances, seeded). A break (dispatch.plan.breaks)
opens when it is due, lasts its service and holds the seats: no rider on board across it.

Held to the reference: the rule over a stop sequence (``timetable``, in Python and compiled,
and ``schedule`` over Stop objects), the compiled insertion (its slack path and its
re-simulating path for plans whose stops wait), the plan change (``insert`` and ``pushed``:
the times the operator keeps after an insertion) and rtv's search over every order
(``best_orders`` with ``reorder``) and over the orders keeping the plan's own (without)."""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest

from dispatch.plan import stops as S
from dispatch.plan._kernel import timetable as compiled_timetable
from dispatch.plan.breaks import BREAK
from dispatch.plan.insertion import insertion_costs
from tests.dispatch.reference import brute_force_insertion, simulate

#: every kind a plan may hold, with what a stop of it changes on board
KINDS = (S.PICKUP, S.DROPOFF, S.CHARGE, S.REPOSITION, BREAK, S.DEPOT)


def _metric(rng):
    pts = rng.uniform(0, 1000, size=(60, 2))

    def tt(a: int, b: int) -> float:
        return float(np.hypot(*(pts[a] - pts[b]))) / 10.0

    return tt


def _stop(rng, kind: str, loc: int, pax: int, ready: float, booked: bool = False):
    """A ``(loc, passengers, latest, service, earliest, holds)`` row of ``kind``: a charger
    visit takes long and may open later (a booked slot), a break opens when it is due, lasts
    its duration and holds the seats, a depot closes at some time; a request's drop-off never
    waits, nor its pickup unless ``booked`` (then some open later: a booked ride's requested
    departure or a walking rider's arrival, its window no sooner closed than opened)."""
    earliest, service, latest = -math.inf, 0.0, math.inf
    if kind == S.PICKUP and booked and rng.random() < 0.5:
        earliest = ready + float(rng.uniform(0, 400))
    if kind == S.CHARGE:
        service = float(rng.uniform(60, 600))
        if rng.random() < 0.5:
            earliest = ready + float(rng.uniform(0, 400))
    elif kind == BREAK:
        earliest = ready + float(rng.uniform(0, 500))
        service = float(rng.uniform(60, 900))
    elif kind == S.REPOSITION:
        if rng.random() < 0.3:
            earliest = ready + float(rng.uniform(0, 200))
    elif kind == S.DEPOT:
        service = float(rng.uniform(0, 120))
        latest = ready + float(rng.uniform(300, 3000))
    elif kind == S.DROPOFF:
        service = float(rng.choice([0.0, 15.0]))
    if kind in (S.PICKUP, S.DROPOFF) and rng.random() < 0.6:
        latest = ready + float(rng.uniform(100, 1500))
    return (loc, pax, latest, service, earliest, kind == BREAK)


def _sequence(rng, ready: float):
    """A random small stop set of every kind (no order implied): ``(rows, load, cap)``."""
    cap = int(rng.integers(1, 4))
    rows, load = [], 0
    for k in range(int(rng.integers(1, 6))):
        kind = KINDS[int(rng.integers(0, len(KINDS)))]
        pax = {S.PICKUP: 1, S.DROPOFF: -1}.get(kind, 0)
        if kind == S.DROPOFF:
            load += 1  # someone on board to drop
        rows.append(_stop(rng, kind, k + 1, pax, ready))
    return rows, min(load, cap), cap


def _rule(first, tt, rows, load, cap, compiled: bool):
    """Arrival times by :func:`dispatch.plan.stops.timetable` (or its compiled twin), None where a
    stop breaks a limit."""
    legs = [tt(a[0], b[0]) for a, b in zip(rows, rows[1:])]  # (the timing: seats aside)
    cols = [legs, [r[4] for r in rows], [r[3] for r in rows], [r[2] for r in rows],
            [r[1] for r in rows]]
    out = [0.0] * len(rows)
    if compiled:
        cols = [np.array(x, float) for x in cols[:4]] + [np.array(cols[4], np.int64)]
        out = np.zeros(len(rows))
    bad, _ = (compiled_timetable if compiled else S.timetable)(first, *cols, load, cap, S.TOL,
                                                               out)
    return None if bad >= 0 else [float(x) for x in out]


@pytest.mark.parametrize("seed", range(4))
def test_timetable_equals_the_reference_over_every_order(seed):
    rng = np.random.default_rng([seed, 28])
    orders = feasible = 0
    for _ in range(60):
        tt = _metric(rng)
        ready = float(rng.uniform(0, 100))
        rows, load, cap = _sequence(rng, ready)
        rows = [r[:5] for r in rows]  # (timetable times a route: a break's seats aside)
        for order in itertools.permutations(rows):
            order = list(order)
            want = simulate(ready, lambda loc: tt(0, loc), tt, order, load, cap)
            first = ready + tt(0, order[0][0])
            got = _rule(first, tt, order, load, cap, False)
            jit = _rule(first, tt, order, load, cap, True)
            assert got == jit  # the compiled rule is the same rule, to the bit
            orders += 1
            if want is None:
                assert got is None, (order, got)
                continue
            feasible += 1
            assert got == pytest.approx(want[0], abs=1e-9)
            # the same schedule from Stop objects and their legs
            plan = [S.Stop(BREAK, None, r[0], r[1], r[2], False,
                           leg=tt(a[0], r[0]) if k else 0.0, earliest=r[4], service=r[3])
                    for k, (a, r) in enumerate(zip([order[0]] + order, order))]
            assert S.schedule(first, plan) == got
    assert feasible > 200 and orders - feasible > 200  # both outcomes exercised


def _plan_case(rng, breaks: bool = True, booked: bool = False):
    """A plan of requests' stops with charge, reposition, depot and (``breaks``) break stops
    among them (some waiting; a break where no one is on board; with ``booked`` pickups that
    open later among them), planned by the rule, limits with random slack; 5 new requests
    (some prebooked: a pickup that opens later)."""
    tt = _metric(rng)
    ready = float(rng.uniform(0, 50))
    cap = int(rng.integers(1, 5))
    load = int(rng.integers(0, cap + 1))
    kinds = [S.DROPOFF] * min(load, 2) + [
        KINDS[int(rng.integers(0, len(KINDS)))] for _ in range(int(rng.integers(0, 4)))]
    rng.shuffle(kinds)
    rows, occ = [], load
    for k, kind in enumerate(kinds):
        if kind == S.PICKUP and occ >= cap:
            kind = S.REPOSITION
        if kind == S.DROPOFF and occ <= 0:
            kind = S.CHARGE
        if kind == BREAK and (occ > 0 or not breaks):  # (no one on board at a break)
            kind = S.REPOSITION
        pax = {S.PICKUP: 1, S.DROPOFF: -1}.get(kind, 0)
        occ += pax
        rows.append(_stop(rng, kind, k + 1, pax, ready, booked))
    got = simulate(ready, lambda loc: tt(0, loc), tt,
                   [(r[0], r[1], math.inf, r[3], r[4], r[5]) for r in rows], load, cap)
    if got is None:  # (a pickup right after a break: the seats are held) once more
        return _plan_case(rng, breaks, booked)
    arr = got[0]
    # (a pickup's window closes no sooner than it opens: a booked ride's from its departure)
    rows = [(r[0], r[1], (max(a, r[4]) if r[1] > 0 else a)
             + float(rng.choice([0.0, rng.uniform(0, 300), math.inf])), r[3], r[4], r[5])
            for r, a in zip(rows, arr)]
    reqs = []
    for _ in range(5):
        p, d = int(rng.integers(20, 60)), int(rng.integers(20, 60))
        n = int(rng.integers(1, cap + 2))
        svc = float(rng.choice([0.0, 15.0]))
        lp = ready + float(rng.uniform(0, 500))
        ep = ready + float(rng.uniform(0, 200)) if rng.random() < 0.2 else -math.inf
        ld = lp + tt(p, d) + float(rng.choice([rng.uniform(0, 400), math.inf]))
        reqs.append((p, d, n, lp, ld, 0.0, svc, ep))
    return dict(tt=tt, ready=ready, cap=cap, load=load, stops=rows, arr=arr, reqs=reqs)


def _insertions(c, objective):
    rows, reqs, tt = c["stops"], c["reqs"], c["tt"]
    k, m = len(rows), len(reqs)
    g = [s[0] for s in rows]
    occ, s_occ = c["load"], []
    for s in rows:
        occ += s[1]
        s_occ.append(c["cap"] if s[5] else occ)  # (a break holds the seats: occupancies())
    return insertion_costs(
        np.zeros(m, np.int64), np.arange(m), ready=[c["ready"]],
        first_tt=[tt(0, r[0]) for r in reqs], off=[0, k], s_arr=c["arr"],
        s_svc=[s[3] for s in rows], s_latest=[s[2] for s in rows], s_occ=s_occ,
        load=[c["load"]], cap=[c["cap"]],
        to_p=np.array([[tt(x, r[0]) for r in reqs] for x in g]).reshape(k, m),
        from_p=np.array([[tt(r[0], x) for x in g] for r in reqs]).reshape(m, k),
        to_d=np.array([[tt(x, r[1]) for r in reqs] for x in g]).reshape(k, m),
        from_d=np.array([[tt(r[1], x) for x in g] for r in reqs]).reshape(m, k),
        pd_tt=[tt(r[0], r[1]) for r in reqs], req_n=[r[2] for r in reqs],
        req_lp=[r[3] for r in reqs], req_ld=[r[4] for r in reqs],
        req_svc_p=[r[5] for r in reqs], req_svc_d=[r[6] for r in reqs], objective=objective,
        s_earliest=[s[4] for s in rows], req_earliest=[r[7] for r in reqs])


def _waiting_case(rng):
    """A vehicle standing at its first stop, a booked pickup that opens later (it waits
    there: the stop's arrival is now, as its plan times it while it waits), then a plan as
    :func:`_plan_case` draws one with booked pickups among its stops (the rider picked up
    first rides to the end of it)."""
    while True:
        c = _plan_case(rng, breaks=False, booked=True)
        tt, ready, cap, load = c["tt"], c["ready"], c["cap"], c["load"]
        if load >= cap:
            continue
        e = ready + float(rng.uniform(30, 400))
        rows = [(0, 1, math.inf, 0.0, e, False)] \
            + [(r[0], r[1], math.inf, r[3], r[4], r[5]) for r in c["stops"]] \
            + [(int(rng.integers(20, 60)), -1, math.inf, 0.0, -math.inf, False)]
        got = simulate(ready, lambda loc: tt(0, loc), tt, rows, load, cap)
        if got is None:  # (the extra rider over the seats somewhere) once more
            continue
        arr = got[0]
        assert arr[0] == ready  # (it stands there: tt(0, 0) = 0)
        rows = [(r[0], r[1], (max(a, r[4]) if r[1] > 0 else a)
                 + float(rng.choice([0.0, rng.uniform(0, 300), math.inf])), r[3], r[4], r[5])
                for r, a in zip(rows, arr)]
        return {**c, "stops": rows, "arr": arr}


CASES = {"plan": _plan_case, "booked": lambda rng: _plan_case(rng, booked=True),
         "waiting": _waiting_case}


@pytest.mark.parametrize("case", list(CASES))
@pytest.mark.parametrize("objective", [S.PICKUP_TIME, S.ADDED_TIME])
def test_insertion_with_every_stop_kind_equals_the_reference(objective, case):
    rng = np.random.default_rng(28 + objective)
    cases = feasible = waited = 0
    while cases < 400:
        c = CASES[case](rng)
        cases += 1
        got = _insertions(c, objective)
        tt, ready = c["tt"], c["ready"]
        waited += any(s[4] > ready for s in c["stops"]) or any(r[7] > ready for r in c["reqs"])
        for q, req in enumerate(c["reqs"]):
            want = brute_force_insertion(ready, lambda loc: tt(0, loc), c["stops"], c["load"],
                                         c["cap"], req, tt, objective)
            if math.isinf(want[0]):
                assert math.isinf(got.cost[q]), (q, want, got.of(q))
                continue
            feasible += 1
            assert got.cost[q] == pytest.approx(want[0], abs=1e-6), (want, got.of(q))
            assert got.pickup_at[q] == pytest.approx(want[3], abs=1e-6)
    assert feasible > 300 and waited > 100


@pytest.mark.parametrize("case", list(CASES))
def test_the_plan_change_keeps_the_rule(case):
    """After :func:`insert` of a request where the compiled insertion says, the times the
    operator keeps (:func:`pushed`, then the pickup's and drop-off's) are the rule's for the
    new plan, waits for charge slots, wait stops and booked pickups included, and for a
    vehicle waiting at its first stop (its times from now: inserted before that stop, the
    request's stops are driven first and the stop is reached later)."""
    rng = np.random.default_rng(5)
    checked = before = 0
    while checked < 300:
        c = CASES[case](rng)
        if not c["stops"]:
            continue
        got = _insertions(c, S.ADDED_TIME)
        tt, ready = c["tt"], c["ready"]
        plan = [S.Stop(BREAK if s[5] else S.REPOSITION, None, s[0], s[1], s[2], False,
                       earliest=s[4], service=s[3], holds_seats=s[5]) for s in c["stops"]]
        for q, (p, d, n, lp, ld, sp, sd, ep) in enumerate(c["reqs"]):
            if math.isinf(got.cost[q]):
                continue
            at = got.of(q)
            new = [(p, n, lp, sp, ep), (d, -n, ld, sd, -math.inf)]
            want = simulate(ready, lambda loc: tt(0, loc), tt,
                            S.insert(list(c["stops"]), new, at.i, at.j), c["load"], c["cap"])
            assert want is not None
            times = S.pushed(list(c["arr"]), plan, at.i, at.j, at.shift1, at.shift2)
            times = S.insert(times, [at.pickup_at, at.dropoff_at], at.i, at.j)
            assert times == pytest.approx(want[0], abs=1e-6)
            checked += 1
            before += at.i == 0
    assert before > 50  # (insertions before the first stop: for "waiting", the stop it waits at)


def _rtv_case(rng, nplan_max=4):
    """One vehicle with a plan of every kind and a group of 1-2 new requests (some pickups
    with an earliest time, as a booked request's), as rtv's kernel takes them, and the same as
    reference rows."""
    c = _plan_case(rng, breaks=False)  # (rtv refuses breaks: the scenario check)
    c["stops"] = c["stops"][:nplan_max]
    c["arr"] = c["arr"][:nplan_max]
    c["reqs"] = c["reqs"][:int(rng.integers(1, 3))]
    return c


def _rtv_arrays(c):
    """rtv's kernel arrays of case ``c``: the vehicle and plan, the group, the drives."""
    tt, rows, reqs = c["tt"], c["stops"], c["reqs"]
    k, m = len(rows), len(reqs)
    locs_new = [x for r in reqs for x in (r[0], r[1])]
    ready = c["ready"]
    first_eta = c["arr"][0] if k else ready
    end_old = ready if not k else S.leave(c["arr"][-1], rows[-1][4], rows[-1][3])
    pp = np.array([tt(a[0], b[0]) for a, b in zip(rows, rows[1:])] + [0.0])
    ppa = np.array([tt(a[0], b[0]) for a in rows for b in rows] or [0.0])
    f = np.array
    args = dict(
        groups=f([list(range(m))], np.int64), gveh=f([0], np.int64), start=f([ready]),
        first_eta=f([first_eta]), load=f([c["load"]], np.int64), cap=f([c["cap"]], np.int64),
        off=f([0, k], np.int64), p_pax=f([r[1] for r in rows], np.int64).reshape(k),
        p_limit=f([r[2] for r in rows], float).reshape(k),
        p_svc=f([r[3] for r in rows], float).reshape(k),
        p_eta=f(c["arr"], float).reshape(k), p_drop=np.zeros(k, bool),
        p_e=f([r[4] for r in rows], float).reshape(k))
    vn = f([[tt(0, x) for x in locs_new]])
    pn = f([[tt(r[0], x) for x in locs_new] for r in rows]).reshape(k, 2 * m)
    np_ = f([[tt(x, r[0]) for r in rows] for x in locs_new]).reshape(2 * m, k)
    nn = f([[tt(x, y) for y in locs_new] for x in locs_new])
    reqs_args = dict(
        vn=vn, pn=pn, np_=np_, nn=nn, r_pax=f([r[2] for r in reqs], np.int64),
        r_lp=f([r[3] for r in reqs]), r_ld=f([r[4] for r in reqs]), r_rel=np.zeros(m),
        r_direct=np.zeros(m), r_hasdrop=np.ones(m, bool), r_e=f([r[7] for r in reqs]),
        until=f([c.get("until", math.inf)]), old_end=f([end_old]))
    return args, reqs_args, pp, ppa


def _rtv_reference(c, keep_plan_order: bool):
    """The least added time over every order of the plan's stops and the group's (each
    pickup before its drop-off; with ``keep_plan_order`` the plan's order kept), simulated by
    the reference: the plan's first stop, reached first, at its planned time (the drive the
    vehicle is on); any other first stop by the drive from where the vehicle is; a new pickup
    waits for its earliest time; an order leaving its last stop after ``c["until"]`` (where
    given) is out."""
    tt, rows, reqs, ready = c["tt"], c["stops"], c["reqs"], c["ready"]
    svc = reqs[0][6]
    items = [("plan", u) for u in range(len(rows))] + \
        [(x, i) for i in range(len(reqs)) for x in ("p", "d")]
    end_old = ready if not rows else S.leave(c["arr"][-1], rows[-1][4], rows[-1][3])
    best = math.inf
    for order in itertools.permutations(items):
        seen, ok, last_plan = set(), True, -1
        for it in order:
            if it[0] == "d" and ("p", it[1]) not in seen:
                ok = False
            if it[0] == "plan":
                if keep_plan_order and it[1] != last_plan + 1:
                    ok = False
                last_plan = it[1]
            seen.add(it)
        if not ok:
            continue
        plan = []
        for kind, u in order:
            if kind == "plan":
                plan.append(rows[u])
            else:
                p, d, n, lp, ld = reqs[u][:5]
                plan.append((p, n, lp, 0.0, reqs[u][7]) if kind == "p" else
                            (d, -n, ld, svc, -math.inf))
        head = order[0] == ("plan", 0)

        def first_tt(loc, head=head):
            return c["arr"][0] - ready if head else tt(0, loc)

        got = simulate(ready, first_tt, tt, plan, c["load"], c["cap"])
        if got is not None and got[1] <= c.get("until", math.inf) + S.TOL:
            best = min(best, got[1] - end_old)
    return best


@pytest.mark.parametrize("reorder,until", [(False, False), (True, False), (False, True),
                                           (True, True)])
def test_rtv_orders_with_every_stop_kind_equal_the_reference(reorder, until):
    from allocators._rtv_kernel import best_orders

    rng = np.random.default_rng(280 + reorder + 2 * until)
    feasible = cases = waits = ended = 0
    while cases < 400:
        c = _rtv_case(rng, 3 if reorder else 4)  # (every order of up to 7 stops)
        waits += any(r[7] > -math.inf for r in c["reqs"])
        if until:  # a shift's end: the route leaves its last stop by it
            c["until"] = c["ready"] + float(rng.uniform(200.0, 2000.0))
        # (rtv's plans: a stop's limit is at least its planned time; drop-offs serve)
        c["stops"] = [(r[0], r[1], max(r[2], a), r[3], r[4]) for r, a in zip(c["stops"], c["arr"])]
        svc = float(rng.choice([0.0, 15.0]))
        c["reqs"] = [r[:6] + (svc, r[7]) for r in c["reqs"]]
        cases += 1
        args, rargs, pp, ppa = _rtv_arrays(c)
        k, m = len(c["stops"]), len(c["reqs"])
        L = k + 2 * m
        out = (np.full(1, np.inf), np.full((1, L), -99, np.int64), np.zeros(1, bool),
               np.full(1, np.nan))
        common = [args[x] for x in ("groups", "gveh", "start", "first_eta", "load", "cap", "off",
                                    "p_pax", "p_limit", "p_svc", "p_eta", "p_drop", "p_e")]
        tail = [rargs[x] for x in ("vn", "pn", "np_", "nn", "r_pax", "r_lp", "r_ld", "r_rel",
                                   "r_direct", "r_hasdrop", "r_e", "until", "old_end")]
        if reorder:  # (the arrays the other mode reads are left empty)
            vp = np.array([c["tt"](0, r[0]) for r in c["stops"]]).reshape(k)
            best_orders(*common, np.zeros(0), np.full(k, -1, np.int64), vp,
                        np.zeros(1, np.int64), ppa, *tail, svc, 1, 10**7, S.TOL, True, *out)
        else:
            best_orders(*common, pp, np.zeros(0, np.int64), np.zeros(0), np.zeros(0, np.int64),
                        np.zeros(0), *tail, svc, 1, 10**7, S.TOL, False, *out)
        want = _rtv_reference(c, keep_plan_order=not reorder)
        if math.isinf(want):
            assert math.isinf(out[0][0]), (want, out)
            if until:  # (the shift's end alone ruled every order out)
                ended += math.isfinite(_rtv_reference({**c, "until": math.inf},
                                                      keep_plan_order=not reorder))
            continue
        feasible += 1
        assert out[0][0] == pytest.approx(want, abs=1e-6)
        # the added-time objective: the route ends that much after the plan's old end
        assert out[3][0] == pytest.approx(rargs["old_end"][0] + out[0][0], abs=1e-6)
    # both outcomes exercised, new pickups that wait, routes only the shift's end rules out
    assert (20 if until else 50) < feasible < cases and waits > 20
    assert ended > 3 or not until
