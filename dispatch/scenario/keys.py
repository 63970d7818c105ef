"""The keys of a scenario file's top level and of its tables that are read before, or with,
the files a scenario names: checked over the whole document before any value is read, so that
a misspelt key is reported before a large or broken trace is read (:func:`check_keys`).

The other sections (``[world]``, ``[faults]``, ``[reposition]``, ...) check their keys when
they are read (:meth:`dispatch.scenario.toml_table.Table.done`). A parser that reads a key of a
table declared here, and not declared, has a bug (``LookupError``).
"""

from __future__ import annotations

from pathlib import Path

from dispatch.scenario.toml_table import Table

#: the keys of each table declared here, by section ("": the top level)
KEYS: dict[str, tuple[str, ...]] = {
    "": ("name", "description", "seed", "duration", "world", "fleet", "tasks", "dispatch",
         "comms", "faults", "sweep", "reposition", "chargers", "charging", "pricing",
         "acceptor", "transit"),
    "fleet": ("agents", "uav_fraction", "uav_speed", "ugv_speed", "uav_max_start_altitude",
              "placement", "capacity", "start", "energy", "breaks", "sizing", "sizing_params",
              "shift_grace"),
    "tasks": ("source", "count", "interval", "rate", "max_active", "ground_fraction",
              "service_time", "ttl", "max_wait", "max_delay", "max_walk", "walk_speed",
              "meeting_points", "trips_per_day", "weekday", "prebook_share", "prebook_lead",
              "trace", "id_column", "start", "max_snap"),
    "dispatch": ("allocator", "planner", "batch_window", "max_rounds", "reassign", "lazy_costs",
                 "objective", "allocator_params", "planner_params", "prebook", "prebook_lead",
                 "out_of_reach"),
    "comms": ("range", "latency", "loss"),
    "sweep": ("allocator", "planner", "agents", "seed", "batch_window", "reposition"),
}


def check_keys(path: Path, doc: dict) -> None:
    """Raise ScenarioError for the first key of ``doc`` (a decoded scenario file) that
    :data:`KEYS` does not know, naming the closest known one; a table that is not a table is
    left to its parser."""
    Table(path, "", doc).expect(KEYS[""])
    for section, keys in KEYS.items():
        if section and isinstance(doc.get(section), dict):
            Table(path, f"{section}.", doc[section]).expect(keys)
