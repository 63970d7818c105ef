"""Refusals the soak and the fuzz run asked for: a periodic process whose period is so short
it would loop in (almost) no simulated time is refused by the work bounds, one line naming
the file and the key; a plugin parameter its constructor does not take (a typo) is one line
naming the file and the parameter's key, with the closest name, not Python's TypeError."""

from __future__ import annotations

import pytest

from dispatch.errors import DispatchError
from dispatch.run.parser import parser
from dispatch.run.prepare import checked_specs
from dispatch.scenario.load import check_limits, load_scenario
from tests.dispatch.test_trips import road_scenario, write_csv

ENERGY = ('[fleet.energy]\nbattery_kwh = 10.0\n[chargers]\nfile = "st.csv"\n[charging]\n'
          'strategy = "threshold"\ninterval = 60.0\n')


def _scenario(tmp_path, *, fleet: str = 'start = "fleet.csv"', extra: str = ""):
    write_csv(tmp_path / "trips.csv", ["t", "origin_node", "dest_node"], [(1.0, 0, 5)])
    write_csv(tmp_path / "fleet.csv", ["vehicle_id", "node", "shift_start", "shift_end"],
              [(0, 1, 0, 3000)])
    write_csv(tmp_path / "st.csv", ["station_id", "node", "plugs", "kw"], [("S", 2, 1, 3.6)])
    return road_scenario(tmp_path, tasks='source = "trace"\ntrace = "trips.csv"',
                         fleet=fleet, extra=extra, duration=3600.0, allocator="hungarian")


def _refusal(path) -> str:
    sc = load_scenario(path)
    with pytest.raises(DispatchError) as e:
        check_limits(sc, sc.runs())
    return str(e.value)


@pytest.mark.parametrize("fleet, extra, key", [
    ('start = "fleet.csv"\n' + ENERGY.replace("60.0", "1e-300"), "", "charging.interval"),
    ('start = "fleet.csv"\n' + ENERGY.replace("battery_kwh = 10.0",
                                               "battery_kwh = 10.0\nsample = 1e-6"), "",
     "fleet.energy.sample"),
    ('start = "fleet.csv"\nsizing = "utilization"\n[fleet.sizing_params]\ninterval = 1e-9', "",
     "fleet.sizing_params.interval"),
    ('start = "fleet.csv"', '[reposition]\npolicy = "demand"\ninterval = 1e-12',
     "reposition.interval"),
])
def test_a_period_too_short_is_refused_naming_its_key(tmp_path, fleet, extra, key):
    path = _scenario(tmp_path, fleet=fleet.replace("\n[fleet.energy]", "\n\n[fleet.energy]"),
                     extra="\n" + extra if extra else "")
    msg = _refusal(path)
    assert msg.startswith(f"{path}: {key}: ") and "calls in 3600 s (more than 2,000,000)" in msg
    assert "\n" not in msg


def test_a_usual_period_passes(tmp_path):
    sc = load_scenario(_scenario(tmp_path, fleet='start = "fleet.csv"\n\n' + ENERGY))
    check_limits(sc, sc.runs())


def _prepared_error(path) -> str:
    args = parser().parse_args(["run", str(path)])
    with pytest.raises(DispatchError) as e:
        checked_specs(args)
    return str(e.value)


@pytest.mark.parametrize("fleet, extra, key, words", [
    ('agents = 2', '[dispatch.allocator_params]\nvalue_wieght = 1.0',
     "dispatch.allocator_params.value_wieght",
     "allocator 'hungarian' takes no parameter 'value_wieght' (did you mean 'value_weight'?)"),
    ('agents = 2', '[dispatch.allocator_params.hungarian]\nvalu = 1.0',
     "dispatch.allocator_params.hungarian.valu", "(did you mean 'value'?)"),
    ('agents = 2', '[dispatch.planner_params]\nspeeed = 3', "dispatch.planner_params.speeed",
     "planner 'dijkstra' takes no parameter 'speeed'"),
    ('agents = 2', '[reposition]\npolicy = "demand"\n[reposition.demand]\nzonee = 100.0',
     "reposition.demand.zonee", "(did you mean 'zone'?); its parameters: zone, max_moves"),
    ('start = "fleet.csv"\n\n' + ENERGY + '[charging.threshold]\nlo = 0.1', '',
     "charging.threshold.lo", "charger 'threshold' takes no parameter 'lo' (did you mean 'low'?)"),
    ('agents = 2', '[acceptor]\nname = "logit"\n[acceptor.logit]\nb_waitt = -0.1',
     "acceptor.logit.b_waitt", "(did you mean 'b_wait'?)"),
    ('start = "fleet.csv"\nsizing = "utilization"\n[fleet.sizing_params]\nmin_vehicle = 1', '',
     "fleet.sizing_params.min_vehicle", "(did you mean 'min_vehicles'?)"),
])
def test_a_plugin_parameter_typo_is_one_line_naming_its_key(tmp_path, fleet, extra, key, words):
    path = _scenario(tmp_path, fleet=fleet, extra="\n" + extra if extra else "")
    msg = _prepared_error(path)  # ([acceptor.*] is refused while the file is read)
    assert msg.startswith(f"{path}: {key}: "), msg
    assert words in msg and "TypeError" not in msg and "\n" not in msg

