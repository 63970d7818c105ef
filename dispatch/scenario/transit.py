"""``[transit]`` read into :class:`dispatch.config.transit.TransitConfig`: its keys checked
(a misspelt one named with the closest known key), the mode choice loaded and built with its
``[transit.<mode_choice>]`` parameters, and the feed read for the service day, so that a bad
feed is one line naming the scenario's key and the feed's file before a run starts."""

from __future__ import annotations

import datetime as dt
from dataclasses import replace
from pathlib import Path

from dispatch.api.space import space_class
from dispatch.config.transit import TransitConfig
from dispatch.config.world import WorldConfig
from dispatch.scenario.toml_table import Table

#: the keys of ``[transit]`` (besides the ``[transit.<mode_choice>]`` table)
KEYS = ("feed", "service_date", "max_access_walk", "walk_speed", "transfer_walk", "min_change",
        "w_ivt", "w_wait", "w_walk", "w_transfer", "transfer_penalty", "mode_choice")


def _date(t: Table) -> dt.date:
    """``service_date``: a TOML date (``2026-09-23``) or a string ``"2026-09-23"`` /
    ``"20260923"``."""
    v = t.get("service_date")
    if isinstance(v, dt.datetime):
        raise t.fail("service_date", f"must be a date, not a date-time ({v.isoformat()})")
    if isinstance(v, dt.date):
        return v
    if isinstance(v, str):
        for fmt in ("%Y-%m-%d", "%Y%m%d"):
            try:
                return dt.datetime.strptime(v, fmt).date()
            except ValueError:
                continue
    raise t.fail("service_date", f"must be a date such as 2026-09-23, got {v!r}")


def _mode_choice(t: Table) -> tuple[str, tuple]:
    """The mode choice's name and parameters, checked by building it."""
    from dispatch.api import registry
    from dispatch.errors import PluginError

    name = t.string("mode_choice")
    if name not in registry.available("mode_choice"):
        raise t.fail("mode_choice", registry.unknown("mode_choice", name))
    for k in sorted(k for k in t.data if isinstance(t.data[k], dict)):
        if k != name:
            raise t.fail(k, f"parameters of mode choice {k!r}, which does not run (mode_choice "
                            f"is {name!r})")
    params = t.params(name) if name in t.data else ()
    try:
        cls = registry.load("mode_choice", name)
        cls(**dict(params))
    except PluginError as e:
        raise t.fail("mode_choice", str(e)) from None
    except (TypeError, ValueError) as e:
        raise t.fail(name, " ".join(str(e).split()) or type(e).__name__) from None
    return name, tuple(params)


def parse_transit(t: Table, path: Path, world: WorldConfig, reassign: bool = False
                  ) -> TransitConfig:
    """``[transit]`` (see :class:`~dispatch.config.transit.TransitConfig`), on a road network
    with a CRS (riders' doors and the stations are placed on it), without re-assignment
    before pickup (``reassign``: a booked last leg waits in a vehicle's plan, which
    re-assignment gives up whole, as with prebooking)."""
    from dispatch.errors import ScenarioError
    from dispatch.files.gtfs import feed_path, load_feed

    given = t.data.get("mode_choice")
    t.expect((*KEYS, given if isinstance(given, str) else t.default("mode_choice")))
    if "snap" not in space_class(world.space).features:
        raise t.fail(next(iter(t.data), "feed"), "transit needs a road network "
                                                 "([world] network)")
    if reassign:
        raise ScenarioError(path, "dispatch.reassign", "re-assignment before pickup and "
                                                       "[transit] do not go together")
    feed = t.string("feed")
    cfg = TransitConfig(
        feed=feed, service_date=_date(t),
        max_access_walk=t.number("max_access_walk", lo=0.0),
        walk_speed=t.number("walk_speed", gt=0.0),
        transfer_walk=t.number("transfer_walk", lo=0.0),
        min_change=t.number("min_change", lo=0.0),
        w_ivt=t.number("w_ivt", lo=0.0), w_wait=t.number("w_wait", lo=0.0),
        w_walk=t.number("w_walk", lo=0.0), w_transfer=t.number("w_transfer", lo=0.0),
        transfer_penalty=t.number("transfer_penalty", lo=0.0))
    name, params = _mode_choice(t)
    t.done()
    where = feed_path(feed, path.parent).resolve()
    with t.reading("feed", where):
        load_feed(where, cfg.service_date)  # kept for the run (read once per file and day)
    return replace(cfg, mode_choice=name, params=params, feed_path=where)
