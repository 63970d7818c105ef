"""Electric fleets ([fleet.energy], [chargers], [charging]): energy by hand on a 6 x 2 grid,
a stranding by hand, the charging taper by hand, conservation and station capacity on random
runs with breakdowns, a battery too small for any trip, same seed same output, and the
strategies on a tiny network with a known answer."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from dispatch.checks.chargers import charging_views, check_charger
from dispatch.errors import ScenarioError
from dispatch.fleet.chargers import charge_seconds, power_kw, soc_after
from dispatch.output.parquet import TIMING_COLUMNS
from dispatch.run.runner import run_one
from dispatch.scenario.load import load_scenario

GRID = 'network = "manhattan"\nblocks = [6, 2]\nblock = 200.0\nspeed = 10.0'
TERMINAL = {"completed", "expired", "rejected", "unreachable", "cut_off", "failed"}


def grid(d: Path, energy: str, trips, starts=(0,), extra: str = "", name="ev",
         duration: float = 1e5) -> Path:
    (d / "fleet.csv").write_text("vehicle_id,node\n" + "".join(f"{i},{n}\n"
                                                                for i, n in enumerate(starts)))
    (d / "trips.csv").write_text("t,origin_node,dest_node\n" + "".join(
        f"{t},{o},{e}\n" for t, o, e in trips))
    p = d / f"{name}.toml"
    p.write_text(f'name = "{name}"\nseed = 1\nduration = {duration!r}\n[world]\n{GRID}\n'
                 f'[fleet]\nstart = "fleet.csv"\n[fleet.energy]\n{energy}\n[tasks]\n'
                 f'source = "trace"\ntrace = "trips.csv"\nmax_wait = 600.0\n[dispatch]\n'
                 f'allocator = "fcfs"\n{extra}', encoding="utf-8")
    return p


def run(path: Path):
    [spec] = load_scenario(path).runs()
    r = run_one(spec)
    return r.summary, {n: t.to_pandas() for n, t in r.tables.items()}


# ----------------------------------------------------------------------------- by hand


def test_energy_of_a_trip_by_hand(tmp_path):
    # node 0 -> pickup node 2 (400 m, 40 s) -> drop-off node 8 (200 m, 20 s), done at t = 70:
    # 600 m at 150 Wh/km = 0.09 kWh, plus 0.36 kWh/h over 70 s = 0.007 kWh
    s, t = run(grid(tmp_path, "battery_kwh = 1.0\nwh_per_km = 150.0\nidle_kwh_per_hour = 0.36\n"
                              "soc0 = 0.5\nreserve = 0.1", [(10.0, 2, 8)]))
    v = t["vehicles"].iloc[0]
    assert s["tasks_completed"] == 1 and v.distance == pytest.approx(600.0)
    assert v.kwh_drawn == pytest.approx(0.097, abs=1e-12)
    assert v.kwh_charged == 0.0 and v.soc_end == pytest.approx(0.403, abs=1e-12)
    assert v.soc_min == pytest.approx(v.soc_end)
    assert "chargers" in t and len(t["chargers"]) == 0


def test_speed_table_and_reserve(tmp_path):
    # 36 km/h on the table [[0, 100], [72, 300]]: 200 Wh/km -> 600 m draw 0.12 kWh
    s, t = run(grid(tmp_path, "battery_kwh = 1.0\nwh_per_km = [[0.0, 100.0], [72.0, 300.0]]",
                    [(10.0, 2, 8)]))
    assert t["vehicles"].iloc[0].kwh_drawn == pytest.approx(0.12, abs=1e-12)
    # the same trip with 0.1 kWh and a reserve of 10 %: 0.1 - 0.12 < 0.01: never a candidate
    s, t = run(grid(tmp_path, "battery_kwh = 0.1\nwh_per_km = [[0.0, 100.0], [72.0, 300.0]]",
                    [(10.0, 2, 8)], name="low"))
    assert s["tasks_completed"] == 0 and set(t["tasks"].state) == {"expired"}
    assert t["vehicles"].iloc[0].kwh_drawn == 0.0


def test_a_vehicle_strands_where_its_battery_runs_empty(tmp_path):
    # 0.1 kWh, 150 Wh/km, 7.2 kWh/h auxiliary (0.002 kWh/s); the reserve rule sees 0.09 kWh
    # of driving and lets it go. Leg 1 would need 0.06 + 0.08 kWh: it is empty after
    # 40 * 0.1 / 0.14 = 28.571 s, 285.7 m along (past node 1, on 1 -> 2): stranded there,
    # its request re-opened; towed after 100 s but empty: the request expires at 600 s
    s, t = run(grid(tmp_path, "battery_kwh = 0.1\nwh_per_km = 150.0\nidle_kwh_per_hour = 7.2\n"
                              "reserve = 0.0", [(0.0, 2, 8)], extra="[faults]\ntow = 100.0\n"))
    ev = t["events"]
    st = ev[ev.event == "stranded"].iloc[0]
    assert st.t == pytest.approx(40 * 0.1 / 0.14) and st.x == pytest.approx(2000 / 7)
    assert list(ev[ev.t == st.t].event) == ["stranded", "breakdown", "reopen"]
    v = t["vehicles"].iloc[0]
    assert v.soc_end == pytest.approx(0.0, abs=1e-12) and v.soc_min >= 0.0
    assert v.kwh_drawn == pytest.approx(0.1, abs=1e-12)
    assert v.distance == pytest.approx(2000 / 7)
    assert t["tasks"].state.tolist() == ["expired"]
    assert (ev.event == "repair").sum() == 1


def test_taper_by_hand():
    # 50 kWh at 50 kW: 20 % -> 80 % flat, 0.6 h; 80 % -> 100 % from 50 down to 10 kW, linear
    # in soc: dt = 50 / (50 * 4) * ln(1 / (1 - 4 * 0.2)) h = 0.25 ln 5 h
    assert charge_seconds(0.2, 0.8, 50, 50, 0.8, 0.2) == pytest.approx(2160.0)
    assert charge_seconds(0.8, 1.0, 50, 50, 0.8, 0.2) == pytest.approx(900 * math.log(5))
    assert charge_seconds(0.2, 1.0, 50, 50, 0.8, 0.2) == pytest.approx(2160 + 900 * math.log(5))
    assert power_kw(0.9, 50, 0.8, 0.2) == pytest.approx(30.0)
    for a, b in ((0.1, 0.5), (0.3, 0.95), (0.85, 0.99)):
        t = charge_seconds(a, b, 50, 50, 0.8, 0.2)
        assert soc_after(a, t, 50, 50, 0.8, 0.2) == pytest.approx(b, abs=1e-12)


def test_a_vehicle_charges_at_a_station_by_hand(tmp_path):
    # soc 0.15 of 1 kWh at node 0, a 3.6 kW station at node 1 (20 s away): threshold 0.2 ->
    # 0.5 at the first call (t = 60): drive 200 m (0.03 kWh) -> 0.12, charge 0.38 kWh at
    # 3.6 kW flat (taper from 0.8): 380 s; trip at 1000 s keeps the run going
    (tmp_path / "st.csv").write_text("station_id,node,plugs,kw\nS,1,1,3.6\n")
    s, t = run(grid(tmp_path, "battery_kwh = 1.0\nwh_per_km = 150.0\nsoc0 = 0.15\nreserve = 0.5",
                    [(1000.0, 11, 11)],
                    extra='[chargers]\nfile = "st.csv"\n[charging]\nstrategy = "threshold"\n'
                          '[charging.threshold]\nlow = 0.2\nhigh = 0.5\n'))
    ev = t["events"]
    cs, ce = ev[ev.event == "charge_start"].iloc[0], ev[ev.event == "charge_end"].iloc[0]
    assert cs.t == pytest.approx(80.0) and ce.t == pytest.approx(80.0 + 380.0)
    v = t["vehicles"].iloc[0]
    assert v.kwh_charged == pytest.approx(0.38) and v.charge_seconds == pytest.approx(380.0)
    c = t["chargers"].iloc[0]
    assert c.kwh_delivered == pytest.approx(0.38) and c.visits == 1
    assert c.busy_plug_hours == pytest.approx(380 / 3600)


# ----------------------------------------------------------------------------- random runs


def random_run(tmp_path, seed: int, battery=3.0, faults=True, strategy="threshold",
               plugs=(1, 2)) -> tuple[dict, dict]:
    (tmp_path / "st.csv").write_text("station_id,node,plugs,kw\n" + "".join(
        f"S{k},{n},{p},20\n" for k, (n, p) in enumerate(zip((0, 55, 99), plugs + (1,)))))
    f = "[faults]\nrate = 0.5\nrepair = 300.0\ntow = 600.0\n" if faults else ""
    p = tmp_path / f"r{seed}{strategy}.toml"
    p.write_text(f'name = "r"\nseed = {seed}\nduration = 20000.0\n[world]\nnetwork = '
                 f'"manhattan"\nblocks = [10, 10]\nblock = 200.0\nspeed = 10.0\n[fleet]\n'
                 f'agents = 8\ncapacity = 2\n[fleet.energy]\nbattery_kwh = {battery}\n'
                 f'wh_per_km = [[0.0, 120.0], [100.0, 200.0]]\nidle_kwh_per_hour = 0.2\n'
                 f'soc0 = 0.5\nreserve = 0.1\n[chargers]\nfile = "st.csv"\n[charging]\n'
                 f'strategy = "{strategy}"\ninterval = 120.0\n[tasks]\nsource = "poisson"\n'
                 f'rate = 0.02\ncount = 150\nmax_wait = 600.0\nmax_delay = 600.0\n'
                 f'[dispatch]\nallocator = "greedy"\n{f}', encoding="utf-8")
    return run(p)


def check_invariants(s, t, battery):
    v = t["vehicles"]
    kwh0 = 0.5 * battery
    assert np.allclose(kwh0 + v.kwh_charged - v.kwh_drawn, v.soc_end * battery, rtol=0, atol=1e-9)
    assert (v.soc_min >= 0).all() and (v.soc_end >= 0).all() and (v.soc_end <= 1 + 1e-12).all()
    tasks = t["tasks"]
    assert set(tasks.state) <= TERMINAL and len(tasks) == s["n_tasks"] == 150
    # no station charges more vehicles than it has plugs (stations at distinct nodes)
    ev, ch = t["events"], t["chargers"]
    plugs = {(r.x, r.y): r.plugs for r in ch.itertuples()}
    c = ev[ev.event.isin(["charge_start", "charge_end"])].copy()
    c["d"] = np.where(c.event == "charge_start", 1, -1)
    for (x, y), g in c.groupby(["x", "y"]):
        g = g.sort_values(["t", "d"], kind="stable")  # ends before starts at the same time
        assert g.d.cumsum().max() <= plugs[(x, y)]
        assert g.d.sum() >= 0


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_random_runs_with_breakdowns_conserve_energy(tmp_path, seed):
    s, t = random_run(tmp_path, seed)
    check_invariants(s, t, 3.0)
    ev = t["events"]
    assert (ev.event == "charge_start").any() and (ev.event == "breakdown").any()


@pytest.mark.parametrize("strategy", ["idle", "valley"])
def test_every_strategy_runs_with_the_invariants(tmp_path, strategy):
    s, t = random_run(tmp_path, 4, strategy=strategy)
    check_invariants(s, t, 3.0)


def test_a_battery_too_small_for_any_trip(tmp_path):
    s, t = random_run(tmp_path, 5, battery=0.01, faults=False)
    check_invariants(s, t, 0.01)
    assert s["tasks_completed"] == 0
    assert s["tasks_expired"] + s["tasks_rejected"] == 150


def test_same_seed_same_output(tmp_path):
    a = random_run(tmp_path, 7)[1]
    b = random_run(tmp_path, 7)[1]
    for name in a:
        x, y = a[name], b[name]
        cols = [c for c in x.columns if c not in TIMING_COLUMNS]
        pd.testing.assert_frame_equal(x[cols], y[cols])


def test_a_charge_cut_by_the_end_of_the_run_counts(tmp_path):
    # as in the charge by hand, but the run ends at 280 s (its duration): plugged in at 80 s,
    # 200 s of the 380 s charge count: 0.2 kWh at 3.6 kW
    (tmp_path / "st.csv").write_text("station_id,node,plugs,kw\nS,1,1,3.6\n")
    s, t = run(grid(tmp_path, "battery_kwh = 1.0\nwh_per_km = 150.0\nsoc0 = 0.15\nreserve = 0.5",
                    [(1000.0, 10, 11)], duration=280.0,
                    extra='[chargers]\nfile = "st.csv"\n[charging]\nstrategy = "threshold"\n'
                          '[charging.threshold]\nlow = 0.2\nhigh = 0.5\n'))
    assert s["sim_time"] == pytest.approx(280.0)
    v = t["vehicles"].iloc[0]
    assert v.kwh_charged == pytest.approx(0.2) and v.charge_seconds == pytest.approx(200.0)
    assert v.soc_end == pytest.approx(0.12 + 0.2)
    assert t["chargers"].iloc[0].kwh_delivered == pytest.approx(0.2)


def test_a_queue_forms_at_a_one_plug_station(tmp_path):
    # four vehicles, all low, one 1-plug station: one charges, three queue
    (tmp_path / "st.csv").write_text("station_id,node,plugs,kw\nS,1,1,3.6\n")
    s, t = run(grid(tmp_path, "battery_kwh = 1.0\nwh_per_km = 150.0\nsoc0 = 0.15",
                    [(5000.0, 11, 11)], starts=(0, 2, 6, 7),
                    extra='[chargers]\nfile = "st.csv"\n[charging]\nstrategy = "threshold"\n'))
    ev = t["events"]
    assert (ev.event == "queue").sum() == 3 and (ev.event == "charge_start").sum() == 4
    assert (t["vehicles"].queue_seconds > 0).sum() == 3


# ----------------------------------------------------------------------------- strategies


@pytest.mark.parametrize("name", ["threshold", "idle", "valley"])
def test_strategies_pass_check_charger(name):
    from dispatch.api import registry
    report = check_charger(registry.load("charger", name))
    assert report.ok, str(report)


def tiny_view(socs, in_use=(0, 0), waiting=(0, 0)):
    """Vehicles at node 0 of a 6 x 5 grid (100 m blocks, 10 m/s); station a (1 plug) at node
    0, b (1 plug) at node 10, 5 edges = 50 s away; 50 kW, 50 kWh: a mean charge (20 % -> 80 %)
    takes 2,160 s."""
    from dispatch.api.charger import ChargingView
    from dispatch.checks.common import small_network

    n = len(socs)
    ro = np.asarray
    return ChargingView(
        time=0.0, vehicle_ids=ro(np.arange(n) + 1), nodes=ro(np.zeros(n, np.int64)),
        remaining=ro(np.zeros(n)), soc=ro(socs, float), station_ids=("a", "b"),
        station_nodes=ro([0, 10]), plugs=ro([1, 1]), in_use=ro(in_use), waiting=ro(waiting),
        kw=ro([50.0, 50.0]), released_by_hour=ro([0]), battery_kwh=50.0, reserve=0.1,
        space=small_network(), rng=np.random.default_rng(0),
        charge_seconds=lambda a, b, kw: charge_seconds(a, b, 50.0, kw, 0.8, 0.2))


def test_threshold_picks_least_drive_plus_queue():
    from chargers.threshold import ThresholdCharging

    v = tiny_view([0.1, 0.15, 0.05, 0.5])
    assert v.travel_times()[0].tolist() == [0.0, 50.0]
    # lowest first: vehicle 3 (5 %) -> a (0 s); vehicle 1 -> a would wait 2,160 s, b is 50 s
    # away -> b; vehicle 2 -> a (2,160 s) beats b (50 + 2,160 s); vehicle 4 is above low
    got = ThresholdCharging(low=0.2, high=0.8).decide(v)
    assert got == {3: ("a", 0.8), 1: ("b", 0.8), 2: ("a", 0.8)}
    # a's plug taken and one queueing: the first goes to b, the next one to b's queue
    # (50 + 2,160 s) rather than a's (2 x 2,160 s)
    got = ThresholdCharging(low=0.2, high=0.8).decide(tiny_view([0.1, 0.15], (1, 0), (1, 0)))
    assert got == {1: ("b", 0.8), 2: ("b", 0.8)}
    assert ThresholdCharging().decide(tiny_view([0.5, 0.9])) == {}


def test_valley_charges_only_in_valleys():
    from chargers.valley import ValleyCharging

    v = dict(charging_views())["low batteries"]()  # 3 free plugs, socs in [0, 0.3)
    ids = v.vehicle_ids.tolist()
    # hours 0-4 released 10, 20, 30, 40, 30: at 5 h the last full hour (30) is above 0.8 x
    # the mean (26): a peak, only those below low go
    got = ValleyCharging(low=0.05, high=0.9).decide(v)
    assert set(got) == {i for i, x in zip(ids, v.soc) if x < 0.05}
    # a valley (30 < 2.0 x 26): the 3 lowest (as many as the free plugs), and those below low
    got = ValleyCharging(low=0.05, high=0.9, valley=2.0).decide(v)
    lowest = {ids[k] for k in np.argsort(v.soc, kind="stable")[:3]}
    assert set(got) == lowest | {i for i, x in zip(ids, v.soc) if x < 0.05}
    assert all(t == 0.9 for _, t in got.values())


def test_bad_configuration_is_one_clear_error(tmp_path):
    with pytest.raises(ScenarioError, match="wh_per_km"):
        load_scenario(grid(tmp_path, "wh_per_km = [[10.0, 1.0], [5.0, 2.0]]", [(1.0, 1, 2)]))
    with pytest.raises(ScenarioError, match="strategy"):
        load_scenario(grid(tmp_path, "", [(1.0, 1, 2)],
                           extra='[charging]\nstrategy = "nope"\n', name="b"))
    with pytest.raises(ScenarioError, match="soc0"):
        load_scenario(grid(tmp_path, "soc0 = 2.0", [(1.0, 1, 2)], name="c"))


def test_a_strategy_rejecting_its_parameters_stops_validation(tmp_path):
    from dispatch.errors import PluginError
    from dispatch.run.prepare import build_plugins

    p = grid(tmp_path, "battery_kwh = 1.0", [(1.0, 1, 2)],
             extra="[charging.threshold]\nlow = 0.9\nhigh = 0.5\n")
    sc = load_scenario(p)
    with pytest.raises(PluginError, match="charging.threshold: high = 0.5, low = 0.9"):
        build_plugins(sc, sc.runs())


def _ev_with_stations(tmp_path, rows: str, extra: str = "") -> Path:
    """The shipped Manhattan EV scenario with the station file ``rows`` (station_id, lon, lat,
    plugs, kw lines) and ``extra`` lines under [chargers]."""
    root = Path(__file__).resolve().parents[2] / "scenarios"
    (tmp_path / "st.csv").write_text("station_id,lon,lat,plugs,kw\n" + rows)
    text = (root / "nyc_manhattan_ev.toml").read_text().replace(
        'file = "data/nyc_manhattan_ev_stations.csv"', 'file = "st.csv"' + extra)
    text = text.replace('"data/', f'"{root}/data/')
    path = tmp_path / "ev.toml"
    path.write_text(text)
    return path


def test_station_beyond_max_snap_is_refused_naming_it(tmp_path):
    near = "s20,-73.92271,40.86694,20,50.0\n"
    chicago = "loop,-87.63,41.88,4,50.0\n"
    with pytest.raises(ScenarioError, match=r"chargers.file: station 'loop' at lon -87.63, lat "
                                            r"41.88 lies [\d,]+ m from the nearest node of "
                                            r"manhattan_osm, farther than chargers.max_snap = "
                                            r"1000 m"):
        load_scenario(_ev_with_stations(tmp_path, near + chicago))
    sc = load_scenario(_ev_with_stations(tmp_path, near))
    assert sc.charging.max_snap == 1000.0 and len(sc.charging.stations) == 1
    # s20 lies 35 m from its intersection: a tighter limit refuses it too
    with pytest.raises(ScenarioError, match="station 's20'.*chargers.max_snap = 1 m"):
        load_scenario(_ev_with_stations(tmp_path, near, "\nmax_snap = 1.0"))


def test_shipped_ev_stations_lie_within_the_default_snap():
    sc = load_scenario(Path(__file__).resolve().parents[2] / "scenarios" / "nyc_manhattan_ev.toml")
    assert len(sc.charging.stations) == 15 and sc.charging.max_snap == 1000.0
