"""``dispatch replay --kepler``: a road run's vehicle trips as kepler.gl trips GeoJSON.

As HIVE writes them: a FeatureCollection with one LineString per vehicle and state spell
(the fleet states of :func:`analysis.timeline.fleet_states`, with the shifts' ``to_depot``
and ``off_shift`` laid over them as the replay shows them), each position
``[longitude, latitude, 0, epoch seconds]`` and properties ``vehicle_id``, ``state`` and
``passengers`` (riders on board during the spell). Times are the run's simulated seconds plus
``epoch`` (the Unix time of second 0; default 0). Positions are the replay's keyframes (the
recorded positions, drives routed along the fastest streets), turned back from the network's
metres into longitude / latitude with pyproj; a network without a CRS (a generated grid in
plain metres) has no longitude / latitude and gets a clear error.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from analysis.replay import _network, keyframes, route_keyframes
from analysis.replay_data import ReplayInputError, choose_run, read_table
from analysis.replay_duty import duty_spells, overlay
from analysis.timeline import fleet_states


def _to_lonlat(crs: str):
    try:
        from pyproj import CRS, Transformer
    except ImportError:
        raise ReplayInputError("--kepler needs pyproj (pip install pyproj) to turn the "
                               "network's metres into longitude / latitude") from None
    c = CRS.from_user_input(crs)
    unit = c.axis_info[0].unit_conversion_factor if c.axis_info else 1.0
    tr = Transformer.from_crs(c, "EPSG:4326", always_xy=True)

    def convert(x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        return tr.transform(np.asarray(x) / unit, np.asarray(y) / unit)

    return convert


def trips(folder: str | Path, run_id: str | None = None, epoch: float = 0.0) -> dict:
    """The GeoJSON FeatureCollection of the run (see the module docstring)."""
    run = choose_run(folder, run_id)
    if run.metadata.get("dispatch.space") != "road":
        raise ReplayInputError(f"{run.root}: run {run.run_id} is not a road run; kepler.gl "
                               "trips are written for road runs")
    crs = run.metadata.get("dispatch.crs")
    if not crs or crs == "none":
        raise ReplayInputError(f"{run.root}: the network of run {run.run_id} has no CRS "
                               "(plain metres, e.g. a generated grid): no longitude / latitude "
                               "for kepler.gl")
    convert = _to_lonlat(crs)
    tasks = read_table(run, "tasks")
    vehicles = read_table(run, "vehicles").sort_values("agent_id").reset_index(drop=True)
    events = read_table(run, "events")
    kf = keyframes(events, vehicles)
    net = _network(run)
    if net is not None:
        kf = route_keyframes(kf, net[0], net[1], *net[3:])
    riders = (dict(zip(tasks["task_id"].astype(int), tasks["passengers"].fillna(1).astype(int)))
              if len(tasks) else None)
    end = float(events["t"].max()) if len(events) else 0.0
    st = fleet_states(events.assign(run_id=run.run_id), vehicles.assign(run_id=run.run_id),
                      end=end, passengers=riders)
    # the shifts over the fleet states, as the replay shows them (to_depot, off_shift)
    st = overlay(st.sort_values(["agent_id", "start"], kind="stable"),
                 duty_spells(events, vehicles, end))
    lon, lat = convert(kf["x"].to_numpy(), kf["y"].to_numpy())
    kt = kf["t"].to_numpy(dtype=float)
    ka = kf["agent_id"].to_numpy()
    features = []
    for agent, spells in st.groupby("agent_id", sort=True):
        lo, hi = np.searchsorted(ka, agent, "left"), np.searchsorted(ka, agent, "right")
        ts, xs, ys = kt[lo:hi], lon[lo:hi], lat[lo:hi]
        if ts.size == 0:
            continue
        for s in spells.itertuples(index=False):
            inner = np.flatnonzero((ts > s.start) & (ts < s.end))
            tt = np.concatenate([[s.start], ts[inner], [s.end]])
            xx = np.concatenate([[np.interp(s.start, ts, xs)], xs[inner],
                                 [np.interp(s.end, ts, xs)]])
            yy = np.concatenate([[np.interp(s.start, ts, ys)], ys[inner],
                                 [np.interp(s.end, ts, ys)]])
            coords = [[round(float(a), 7), round(float(b), 7), 0, round(float(t) + epoch, 3)]
                      for a, b, t in zip(xx, yy, tt)]
            features.append({"type": "Feature",
                             "geometry": {"type": "LineString", "coordinates": coords},
                             "properties": {"vehicle_id": int(agent), "state": str(s.state),
                                            "passengers": int(s.onboard)}})
    return {"type": "FeatureCollection", "features": features}


def write_trips(folder: str | Path, out: str | Path | None = None, *,
                run_id: str | None = None, epoch: float = 0.0) -> Path:
    """Write :func:`trips` of the run to ``out`` (default ``folder/<run id>.trips.geojson``)."""
    fc = trips(folder, run_id, epoch)
    rid = choose_run(folder, run_id).run_id
    path = Path(out) if out is not None else Path(folder) / f"{rid}.trips.geojson"
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_text(json.dumps(fc, separators=(",", ":")), encoding="utf-8")
    tmp.replace(path)
    return path
