"""The sweep's dimensions, declared once: what names a run.

A run of a scenario is one point of its sweep: an allocator, a planner, a repositioner, a batch
window, a fleet size N and a seed. :data:`RUN_KEYS` lists them (with the scenario, which a
sweep does not vary), in the order of the Hive partitions and of the run id. Everything that
walks the sweep's dimensions reads this tuple: the ``[sweep]`` lists a scenario expands
(:meth:`dispatch.config.scenario.Scenario.runs`), the run's partition and run id
(:class:`dispatch.config.scenario.RunSpec`), the settings a run's point replaces in a scenario's
digest
(:mod:`dispatch.run.resume`), the ``dispatch.run_keys`` metadata every file of a run carries (so
that readers, :mod:`analysis` among them, learn the run keys from the files) and the
instance a run is paired on in the CLI's tables (every run key but the allocator).

An *optional* key (``reposition``, ``batch_window``) is named in the partition path and the run
id only where the scenario declares it (a ``[reposition]`` table or sweep; a ``[sweep]
batch_window`` list), so that the folders and ids of scenarios without it stay as they always
were; the summary has a column for every key whatever the scenario.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

__all__ = ["RUN_KEYS", "RunKey", "key_names", "instance_keys", "point_settings", "run_id",
           "format_value"]


@dataclass(frozen=True)
class RunKey:
    """One dimension of a run.

    ``name``: the summary column, the Hive partition key and the name in ``dispatch.run_keys``.
    ``sweep``: its ``[sweep]`` list (:class:`dispatch.config.sweep.SweepConfig` field; None: not
    swept). ``setting``: ``(table, key)`` of the scenario setting a run's value replaces
    (``""``: top level; None: none). ``tag``: the prefix of its value in the run id.
    ``optional``: named in the partition and run id only where the scenario declares it.
    ``default``: the value of runs whose files lack the key (written before it existed).
    ``digest``: its name in a run's digest (:func:`dispatch.run.resume.run_digest`; kept as the
    digests of earlier versions spelt it, so complete runs stay complete)."""

    name: str
    sweep: str | None
    setting: tuple[str, str] | None
    tag: str = ""
    optional: bool = False
    default: Any = None
    digest: str | None = None
    #: the value's type in the summary (and of the partition value)
    type: Callable[[Any], Any] = str


#: Every run key, in partition and run-id order.
RUN_KEYS: tuple[RunKey, ...] = (
    RunKey("scenario", None, None),
    RunKey("allocator", "allocator", ("dispatch", "allocator"), digest="allocator"),
    RunKey("planner", "planner", ("dispatch", "planner"), digest="planner"),
    RunKey("reposition", "reposition", ("reposition", "policy"), optional=True,
           default="stay", digest="reposition"),
    RunKey("batch_window", "batch_window", ("dispatch", "batch_window"), tag="bw",
           optional=True, default=0.0, digest="batch_window", type=float),
    RunKey("n_agents", "agents", ("fleet", "agents"), tag="n", digest="agents", type=int),
    RunKey("seed", "seed", ("", "seed"), tag="s", digest="seed", type=int),
)


def key_names() -> list[str]:
    """The names of :data:`RUN_KEYS`, in order (what ``dispatch.run_keys`` holds)."""
    return [k.name for k in RUN_KEYS]


def instance_keys() -> tuple[str, ...]:
    """What makes two runs the same problem instance: every run key but the allocator."""
    return tuple(k.name for k in RUN_KEYS if k.name != "allocator")


def point_settings() -> dict[str, tuple[str, ...]]:
    """Scenario settings a run's point replaces (and ``[sweep]`` itself), per table (``""``:
    top level): left out of a scenario's base settings."""
    out: dict[str, tuple[str, ...]] = {"": ("sweep",)}
    for k in RUN_KEYS:
        if k.setting is not None:
            table, key = k.setting
            out[table] = (*out.get(table, ()), key)
    return out


def format_value(value: Any) -> str:
    """A key's value in a path or run id: a float without a needless ``.0`` (``30``, ``2.5``)."""
    return f"{value:g}" if isinstance(value, float) else str(value)


def run_id(partition: dict[str, Any]) -> str:
    """The run id of a run named by ``partition`` (its named keys, in :data:`RUN_KEYS` order):
    the values joined by ``__``, each after its key's tag (``chicago__fcfs__dijkstra__bw30__n50
    __s0``)."""
    tags = {k.name: k.tag for k in RUN_KEYS}
    return "__".join(f"{tags[k]}{format_value(v)}" for k, v in partition.items())
