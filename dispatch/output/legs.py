"""The tables a run writes only where its scenario asks for them, so that every other run's
folder holds exactly :data:`dispatch.output.parquet.SCHEMAS`' tables: ``legs``
(``[transit]``)."""

from __future__ import annotations

import pyarrow as pa

from dispatch.output.parquet import SCHEMAS

_S, _I, _F = pa.string(), pa.int64(), pa.float64()

OPTIONAL_SCHEMAS: dict[str, pa.Schema] = {
    # [transit]: one row per leg of every rider's trip (dispatch.decide.riders): its mode
    # (fleet, train, walk), start and end (simulated seconds; a train leg's departure from
    # from_stop_id and arrival at to_stop_id), where it goes from and to (metres on the road
    # network's frame), the feed's station ids (null: a street node), a train leg's route and
    # trip, a fleet leg's vehicle
    "legs": pa.schema([
        ("run_id", _S), ("request_id", _I), ("leg", _I), ("mode", _S), ("start", _F),
        ("end", _F), ("from_x", _F), ("from_y", _F), ("to_x", _F), ("to_y", _F),
        ("from_stop_id", _S), ("to_stop_id", _S), ("route_id", _S), ("trip_id", _S),
        ("agent_id", _I),
    ]),
}


def schema_of(name: str) -> pa.Schema:
    """The schema of a table, optional or not (KeyError for no table of that name)."""
    return SCHEMAS[name] if name in SCHEMAS else OPTIONAL_SCHEMAS[name]
