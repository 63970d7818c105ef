"""Offers riders may decline (``[acceptor]``, ``[pricing]``; dispatch.api.acceptor): ``always``
changes nothing, even when the offer step runs; a seeded ``logit`` run is reproducible and its
accept share matches the closed form; ``threshold`` declines exactly past its limits;
``declined`` is one terminal state; bad input fails in one line naming the file and key."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from acceptors.logit import LogitAcceptor
from acceptors.threshold import ThresholdAcceptor
from dispatch.api.acceptor import Offer, Pricing, logistic
from dispatch.api.problem import TaskView
from dispatch.errors import ScenarioError
from dispatch.run.runner import run_one
from dispatch.scenario.load import load_scenario
from tests.dispatch.test_trips import road_scenario, write_csv

GRID = 'network = "manhattan"\nblocks = [6, 5]\nblock = 100.0\nspeed = 10.0'
PRICING = "\n[pricing]\nbase = 2.0\nper_km = 1.5\nper_minute = 0.5\nsharing_discount = 0.25\n"
TERMINAL = {"completed": "complete", "expired": "expire", "rejected": "reject",
            "unreachable": "unreachable", "cut_off": "cut_off", "failed": "failed",
            "declined": "decline"}


def _busy_trace(directory: Path, seed: int, n: int = 40) -> None:
    rng = np.random.default_rng(seed)
    rows, t = [], 0.0
    for _ in range(n):
        t += float(rng.exponential(6.0))
        o, d = rng.choice(30, size=2, replace=False)
        rows.append((round(t, 3), int(o), int(d)))
    write_csv(directory / "trips.csv", ["t", "origin_node", "dest_node"], rows)


def _run(directory: Path, *, allocator: str, capacity: int, extra: str = "",
         window: float = 0.0, max_delay: bool = True, seed: int = 5):
    directory.mkdir(parents=True, exist_ok=True)
    _busy_trace(directory, seed)
    tasks = 'source = "trace"\ntrace = "trips.csv"\nmax_wait = 240.0'
    if max_delay and capacity > 1:
        tasks += "\nmax_delay = 300.0"
    path = road_scenario(directory, tasks=tasks, fleet=f"agents = 3\ncapacity = {capacity}",
                         allocator=allocator, network=GRID,
                         extra=f"batch_window = {window}\n{extra}")
    [spec] = load_scenario(path).runs()
    r = run_one(spec)
    return r.summary, {n: t.to_pandas() for n, t in r.tables.items()}


CASES = [("fcfs", 1, 0.0), ("hungarian", 1, 10.0), ("hungarian", 3, 0.0),
         ("greedy", 2, 10.0), ("rtv", 3, 20.0)]


#: the hand-out's other paths: re-assignment before pickup, a decentralized decision that
#: takes simulated time (pairs handed out after the deliberation)
SLOW = [("hungarian", 1, 0.0, "reassign = true\n"), ("greedy", 1, 10.0, "reassign = true\n"),
        ("auction", 1, 0.0, "\n[comms]\nlatency = 0.5\n")]


IDS = [f"{a}-cap{c}-w{w:g}" for a, c, w in CASES] + ["reassign", "reassign-batched",
                                                    "auction-latency"]


@pytest.mark.parametrize("case", [(*c, "") for c in CASES] + SLOW, ids=IDS)
def test_always_reproduces_the_run_without_offers(tmp_path, case):
    """``always`` with fares to record runs the offer step on every pair (a route re-timed
    for nothing, an rng drawn for nothing would show); the run is the default run."""
    allocator, capacity, window, more = case
    base_s, base = _run(tmp_path / "a", allocator=allocator, capacity=capacity, window=window,
                        extra=more)
    named_s, named = _run(tmp_path / "b", allocator=allocator, capacity=capacity,
                          window=window, extra=more + '\n[acceptor]\nname = "always"\n')
    priced_s, priced = _run(tmp_path / "c", allocator=allocator, capacity=capacity,
                            window=window,
                            extra=more + '\n[acceptor]\nname = "always"\n' + PRICING)
    assert base_s["offers"] == 0 and named_s["offers"] == 0  # the step is skipped
    assert base["tasks"]["offers"].eq(0).all() and base["tasks"]["fare"].isna().all()
    tasks = priced["tasks"]
    assert priced_s["offers"] == tasks.offers.sum() > 0
    assert (tasks.offers <= 1).all() and (tasks[tasks.state == "completed"].offers == 1).all()
    assert priced_s["revenue"] == pytest.approx(tasks[tasks.state == "completed"].fare.sum())
    assert priced_s["tasks_declined"] == 0
    for other in (named, priced):
        for name in ("tasks", "events", "vehicles", "decisions"):
            a, b = base[name], other[name]
            cols = [c for c in a.columns if c not in ("run_id", "offers", "fare",
                                                     "cost_seconds", "decide_seconds",
                                                     "alloc_seconds", "agent_seconds")]
            assert a[cols].equals(b[cols]), name
    for k in ("tasks_completed", "distance", "total_cost", "wait_time_mean", "shared_rate"):
        assert np.array_equal([base_s[k]], [priced_s[k]], equal_nan=True), k


LOGIT = '\n[acceptor]\nname = "logit"\nretries = {retries}\n[acceptor.logit]\nb0 = 0.5\n' \
        'b_wait = -0.8\nb_ivt = -0.1\nb_fare = -0.2\n' + PRICING


def _check_terminal(summary: dict, t: dict, retries: int) -> None:
    tasks, ev = t["tasks"], t["events"]
    released = ev[ev.event == "release"]
    assert tasks.task_id.is_unique and sorted(tasks.task_id) == sorted(released.task_id)
    assert tasks.state.isin(TERMINAL).all()
    declines = ev[ev.event == "decline"].groupby("task_id").size()
    declines = declines.reindex(tasks.task_id, fill_value=0).to_numpy()
    declined = (tasks.state == "declined").to_numpy()
    # accepted: it got a vehicle (an offer is made once per request until it accepts; one
    # declined and then expired or cut off before its next offer accepted none)
    accepted = tasks.task_id.isin(ev[ev.event == "assign"].task_id).to_numpy()
    assert (tasks.offers.to_numpy()[accepted] >= 1).all()
    # a decline event per declined offer (the last one is a declined request's close)
    assert (declines == tasks.offers.to_numpy() - accepted).all()
    # every request one terminal event: its state's (a declined one: its last decline)
    others = ev[ev.event.isin(set(TERMINAL.values()) - {"decline"})]
    ends = others.groupby("task_id").size().reindex(tasks.task_id, fill_value=0).to_numpy()
    assert (ends + declined == 1).all()
    assert (tasks.offers[declined] == retries + 1).all()
    assert (tasks.offers <= retries + 1).all()
    # a declined request never had a vehicle: never assigned, picked up or inserted
    gone = set(tasks.task_id[declined])
    assert not set(ev[ev.event.isin(["assign", "pickup", "insert", "dropoff"])].task_id) & gone
    assert (tasks[declined].agent_id == -1).all()
    assert summary["tasks_declined"] == declined.sum() > 0
    assert summary["offers"] == tasks.offers.sum()
    done = tasks.state == "completed"
    assert summary["revenue"] == pytest.approx(tasks.fare[done].sum())
    assert summary["tasks_completed"] == done.sum() > 0


@pytest.mark.parametrize("case", [(*c, "") for c in CASES] + SLOW, ids=IDS)
@pytest.mark.parametrize("retries", [0, 2])
def test_declined_is_one_terminal_state(tmp_path, case, retries):
    allocator, capacity, window, more = case
    s, t = _run(tmp_path, allocator=allocator, capacity=capacity, window=window,
                extra=more + LOGIT.format(retries=retries))
    _check_terminal(s, t, retries)


def test_a_seeded_logit_run_is_reproducible(tmp_path):
    runs = [_run(tmp_path / str(k), allocator="rtv", capacity=3, window=20.0,
                 extra=LOGIT.format(retries=1)) for k in range(2)]
    (s1, t1), (s2, t2) = runs
    for name in ("tasks", "events", "vehicles"):
        cols = [c for c in t1[name].columns if c != "run_id"]
        assert t1[name][cols].equals(t2[name][cols]), name
    assert s1["tasks_declined"] == s2["tasks_declined"] > 0


# ----------------------------------------------------------------------------- closed forms


def _one_origin(directory: Path, origin: int, n: int, extra: str) -> tuple[dict, dict]:
    """One vehicle at node 0; ``n`` trips ``origin -> 0``, 1000 s apart (the vehicle is back
    at node 0, idle, at every release): every offer's wait is the drive 0 -> origin and its
    in-vehicle time the drive back."""
    write_csv(directory / "fleet.csv", ["vehicle_id", "node"], [(0, 0)])
    write_csv(directory / "trips.csv", ["t", "origin_node", "dest_node"],
              [(1000.0 * k, origin, 0) for k in range(n)])
    path = road_scenario(directory, tasks='source = "trace"\ntrace = "trips.csv"',
                         fleet='start = "fleet.csv"', allocator="hungarian", network=GRID,
                         extra=extra, duration=1000.0 * n + 1000.0)
    [spec] = load_scenario(path).runs()
    r = run_one(spec)
    return r.summary, {k: v.to_pandas() for k, v in r.tables.items()}


@pytest.mark.parametrize("origin,b_fare", [(2, -0.2), (14, -0.2), (14, -0.6)])
def test_the_logit_accept_share_matches_the_closed_form(tmp_path, origin, b_fare):
    """400 riders with identical offers (the same wait, ride and fare): the share that
    accepts is within four binomial standard deviations of the logit formula, and the wait
    and the fare move it as their coefficients say."""
    n = 400
    extra = (f'\n[acceptor]\nname = "logit"\n[acceptor.logit]\nb0 = 2.0\nb_wait = -1.5\n'
             f'b_ivt = -0.5\nb_fare = {b_fare}\n' + PRICING)
    s, t = _one_origin(tmp_path, origin, n, extra)
    tasks = t["tasks"]
    assert set(tasks.state) <= {"completed", "declined"} and (tasks.offers == 1).all()
    # the offers: the drive from node 0 to the origin and back (Manhattan metres / 10 m/s)
    x0, y0 = t["vehicles"].x0[0], t["vehicles"].y0[0]
    metres = abs(tasks.x[0] - x0) + abs(tasks.y[0] - y0)
    drive = metres / 10.0
    done = tasks[tasks.state == "completed"]
    assert np.allclose(done.picked_up_at - done.released_at, drive)
    fare = 2.0 + 1.5 * metres / 1000.0 + 0.5 * drive / 60.0
    assert np.allclose(tasks.fare, fare)
    p = logistic(2.0 - 1.5 * drive / 60.0 - 0.5 * drive / 60.0 + b_fare * fare)
    k = len(done)
    assert abs(k - n * p) <= 4.0 * math.sqrt(n * p * (1.0 - p)), (k, n * p)
    assert s["tasks_declined"] == n - k
    assert s["revenue"] == pytest.approx(k * fare)


@pytest.mark.parametrize("max_wait", [10.0, 30.0, 45.0])
def test_threshold_declines_exactly_past_its_wait_limit(tmp_path, max_wait):
    """Trips from every node to node 0, 1000 s apart, one vehicle at node 0: a rider whose
    pickup is more than ``max_wait`` seconds away declines, one exactly at it accepts."""
    write_csv(tmp_path / "fleet.csv", ["vehicle_id", "node"], [(0, 0)])
    write_csv(tmp_path / "trips.csv", ["t", "origin_node", "dest_node"],
              [(1000.0 * k, k, 0) for k in range(1, 30)])
    extra = f'\n[acceptor]\nname = "threshold"\n[acceptor.threshold]\nmax_wait = {max_wait}\n'
    path = road_scenario(tmp_path, tasks='source = "trace"\ntrace = "trips.csv"',
                         fleet='start = "fleet.csv"', allocator="hungarian", network=GRID,
                         extra=extra, duration=40_000.0)
    [spec] = load_scenario(path).runs()
    t = run_one(spec).tables
    tasks, veh = t["tasks"].to_pandas(), t["vehicles"].to_pandas()
    wait = (abs(tasks.x - veh.x0[0]) + abs(tasks.y - veh.y0[0])) / 10.0
    assert set(tasks.state) <= {"completed", "declined"}
    assert ((tasks.state == "declined") == (wait > max_wait + 1e-9)).all()
    if max_wait % 10 == 0:  # (blocks of 100 m at 10 m/s) a rider exactly at the limit
        assert (wait == max_wait).any()
    assert (tasks.state == "declined").any() and (tasks.state == "completed").any()


def _offer(**kw) -> Offer:
    base = dict(request=TaskView(0, "trip", 3, 0.0, 7), vehicle_id=0, now=0.0,
                released_at=0.0, pickup_at=60.0,
                dropoff_at=360.0, direct=240.0, fare=10.0, pooled=False, attempt=1)
    base.update(kw)
    return Offer(**base)


def test_threshold_detour_and_the_offer_arithmetic():
    rng = np.random.default_rng(0)
    o = _offer()
    assert (o.wait, o.ivt, o.detour) == (60.0, 300.0, 60.0)
    assert ThresholdAcceptor(max_wait=60.0, max_detour=60.0).accept(o, rng)
    assert not ThresholdAcceptor(max_wait=59.9).accept(o, rng)
    assert not ThresholdAcceptor(max_detour=59.9).accept(o, rng)
    assert _offer(direct=math.nan).detour == 0.0
    logit = LogitAcceptor(b0=1.0, b_wait=-0.5, b_ivt=-0.1, b_fare=-0.2)
    assert logit.probability(o) == pytest.approx(1 / (1 + math.exp(-(1 - 0.5 - 0.5 - 2.0))))
    assert logistic(-1000.0) == 0.0 and logistic(1000.0) == 1.0
    p = Pricing(base=2.0, per_km=1.0, per_minute=0.5, sharing_discount=0.25)
    assert p.fare(3000.0, 600.0, False) == pytest.approx(10.0)
    assert p.fare(3000.0, 600.0, True) == pytest.approx(7.5)


# ----------------------------------------------------------------------------- bad input

BAD = [
    ("[pricing]\nbase = 2.0\nper_km = -1.0\n", "pricing.per_km", "must be >= 0"),
    ("[pricing]\nper_minute = -0.1\n", "pricing.per_minute", "must be >= 0"),
    ("[pricing]\nsharing_discount = 1.5\n", "pricing.sharing_discount", "must be <= 1"),
    ("[pricing]\nper_km = 1.0\ntip = 3\n", "pricing", "tip"),
    ('[acceptor]\nname = "logitt"\n', "acceptor.name", "did you mean 'logit'"),
    ('[acceptor]\nname = "logit"\nretries = -1\n', "acceptor.retries", "must be >= 0"),
    ('[acceptor]\nname = "logit"\n[acceptor.logit]\nb_fare = -0.1\n', "acceptor.name",
     "add a [pricing] section"),
    ('[acceptor]\nname = "logit"\n[acceptor.logit]\nb_time = 1.0\n', "acceptor.logit",
     "b_time"),
    ('[acceptor]\nname = "threshold"\n[acceptor.threshold]\nmax_wait = -5.0\n',
     "acceptor.threshold", "max_wait must be a number of seconds >= 0"),
    ('[acceptor]\nname = "threshold"\n[acceptor.logit]\nb0 = 1.0\n', "acceptor.logit",
     "does not run"),
    ('[acceptor]\nname = "logit"\ncolour = "red"\n', "acceptor.colour", "unknown key"),
]


@pytest.mark.parametrize("text,key,reason", BAD, ids=[b[1] + "-" + str(i)
                                                      for i, b in enumerate(BAD)])
def test_bad_input_is_one_line_naming_the_file_and_key(tmp_path, text, key, reason):
    path = road_scenario(tmp_path, tasks='source = "static"\ncount = 3', network=GRID,
                         extra="\n" + text)
    with pytest.raises(ScenarioError) as e:
        load_scenario(path)
    msg = str(e.value)
    assert "\n" not in msg and msg.startswith(str(path)) and f": {key}" in msg, msg
    assert reason in msg, msg


def test_pricing_needs_a_road_network(tmp_path):
    path = tmp_path / "voxel.toml"
    path.write_text('name = "v"\n[world]\nsize = [20, 20, 5]\n[world.obstacles]\ncount = 0\n'
                    '[fleet]\nagents = 2\n[pricing]\nper_km = 1.0\n', encoding="utf-8")
    with pytest.raises(ScenarioError, match=r"voxel\.toml: pricing\.per_km: fares need a road"):
        load_scenario(path)
