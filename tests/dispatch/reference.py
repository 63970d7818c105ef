"""Independent references of the plan rules, written plainly (no code shared with the kernel):
the exhaustive insertion search the compiled insertion is held to, and a re-simulation of any
stop order by the schedule rule, in its own words.

The schedule rule: arrival at a stop = departure from the stop before + the drive; service
starts when the vehicle is there and the stop is open (its earliest time); departure = start
+ the stop's service. Feasible: every occupancy within the capacity and every arrival within
its latest time (+1e-9 s). A stop that holds the seats (a driver's break) is made with no one on
board, and the seats stay held until the next stop is reached: no pickup right after it.
"""

from __future__ import annotations

import math

PICKUP_TIME = 0  # (dispatch.plan.stops' objective codes)


def simulate(ready: float, first_tt, tt, plan, load: int, cap: int):
    """``plan``: ``(loc, passengers, latest, service, earliest[, holds])`` rows driven in
    order from where the vehicle stands (it can leave at ``ready``; ``first_tt(loc)`` seconds
    to the first stop, ``tt(a, b)`` between stops); ``holds``: the stop holds the seats (a
    break). Returns ``(arrivals, departure from the last)`` or None where a stop breaks a
    limit."""
    t, occ, prev, arrivals, held = ready, load, None, [], False
    for loc, pax, latest, svc, earliest, *holds in plan:
        t += first_tt(loc) if prev is None else tt(prev, loc)
        if held and pax > 0:
            return None  # the seats are held until this stop is reached
        occ += pax
        if occ > cap or t > latest + 1e-9:
            return None
        held = bool(holds and holds[0])
        if held and occ > 0:
            return None  # no one on board at a break
        arrivals.append(t)
        t = max(t, earliest) + svc
        prev = loc
    return arrivals, t


def brute_force_insertion(ready: float, first_tt, stops: list[tuple], load: int, cap: int,
                          request: tuple, tt, objective: int):
    """The exhaustive search :func:`dispatch.plan.insertion.insertion_costs` must agree with: every
    (pickup, drop-off) position pair, each new plan re-simulated from scratch. ``stops``:
    ``(loc, passengers, latest, service[, earliest])``; ``request``: ``(pickup loc, drop-off
    loc, passengers, pickup latest, drop-off latest, service at pickup, service at drop-off[,
    pickup earliest])``; ``first_tt(loc)``: seconds from the vehicle to ``loc``; ``tt(a, b)``:
    seconds between two locations. Returns ``(cost, i, j, pickup time)`` or ``(inf, -1, -1,
    inf)``."""
    p, d, n, lp, ld, svc_p, svc_d, *rest = request
    ep = rest[0] if rest else -math.inf
    stops = [s if len(s) >= 5 else (*s, -math.inf) for s in stops]
    base = simulate(ready, first_tt, tt, stops, load, cap)
    end_old = ready if not stops else base[1] if base else math.nan
    best = (math.inf, -1, -1, math.inf)
    k = len(stops)
    for i in range(k + 1):
        for j in range(i, k + 1):
            plan = list(stops)
            plan.insert(j, (d, -n, ld, svc_d, -math.inf))
            plan.insert(i, (p, n, lp, svc_p, ep))
            got = simulate(ready, first_tt, tt, plan, load, cap)
            if got is None:
                continue
            arrivals, end = got
            pick = arrivals[i]
            c = pick - ready if objective == PICKUP_TIME else end - end_old
            if c < best[0] - 1e-12 or (c <= best[0] + 1e-12 and pick < best[3] - 1e-9):
                best = (c, i, j, pick)
    return best
