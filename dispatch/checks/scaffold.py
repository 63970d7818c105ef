"""``dispatch new allocator NAME``: a whole allocator plugin package, ready to install.

It writes ``dispatch-NAME/`` holding

* ``pyproject.toml``: the distribution ``dispatch-NAME``, depending on ``dispatch-sim`` (this
  package's distribution), its allocator registered under the entry-point group
  ``dispatch.allocators`` as ``NAME``;
* ``dispatch_NAME/allocator.py``: a working allocator (the cheapest feasible pair first, a
  parameter checked in the constructor) to edit, its docstring saying what the contract asks;
* ``tests/test_allocator.py``: :func:`dispatch.checks.allocators.check_allocator` on it (pytest);
* ``README.md``: install (``pip install -e .``), check (``dispatch check NAME``), use it in a
  scenario.

Installed (``pip install -e dispatch-NAME``), it passes ``dispatch check NAME`` as written.
"""

from __future__ import annotations

import re
from pathlib import Path

from dispatch.api.registry import available
from dispatch.errors import DispatchError

NAME = re.compile(r"^[a-z][a-z0-9_]{0,40}$")

PYPROJECT = '''[build-system]
requires = ["setuptools>=77"]
build-backend = "setuptools.build_meta"

[project]
name = "dispatch-{dist}"
version = "0.1.0"
description = "The {name} allocator for the dispatch simulator"
requires-python = ">=3.11"
# dispatch-sim: the simulator (its contracts and plugin checks); numpy for the cost matrix
dependencies = ["dispatch-sim", "numpy>=1.26"]

[project.optional-dependencies]
test = ["pytest>=8"]

# how the simulator finds it: `dispatch plugins` lists it, scenarios name it "{name}"
[project.entry-points."dispatch.allocators"]
{name} = "{pkg}.allocator:{cls}"

[tool.setuptools]
packages = ["{pkg}"]
'''

ALLOCATOR = '''"""The {name} allocator: the globally cheapest feasible (vehicle, task) pair
first, until no vehicle or task is left (a greedy matching). Edit :meth:`{cls}.allocate`.

The contract (:class:`dispatch.api.contracts.Allocator`): ``allocate(problem)`` gets a read-only
:class:`~dispatch.api.problem.AllocationProblem` (``problem.cost``: the N x M travel seconds of
the idle vehicles to the open tasks, ``inf`` where a vehicle cannot serve a task;
``problem.agent_ids``, ``problem.task_ids``, positions, release times; ``problem.rng``, the
only randomness it may use) and returns an :class:`~dispatch.api.problem.Allocation` of
feasible pairs, each vehicle and task at most once. It must not write to the problem.
``dispatch check {name}`` checks all of this on random problems.
"""

from __future__ import annotations

import numpy as np

from dispatch.api.contracts import Allocation, AllocationProblem, Allocator


class {cls}(Allocator):
    """Cheapest feasible pair first, until no vehicle or task is left (a greedy matching)."""

    name = "{name}"

    def __init__(self, max_pairs: int | None = None) -> None:
        """``max_pairs``: hand out at most this many tasks per decision (None: no limit);
        set from a scenario as ``[dispatch.allocator_params.{name}] max_pairs = 2``."""
        if max_pairs is not None and (isinstance(max_pairs, bool) or int(max_pairs) < 1):
            raise ValueError(f"max_pairs must be an integer >= 1, got {{max_pairs!r}}")
        self.max_pairs = None if max_pairs is None else int(max_pairs)

    def allocate(self, problem: AllocationProblem) -> Allocation:
        cost = np.array(problem.cost, dtype=float)  # a copy to cross out; problem.cost stays
        limit = self.max_pairs or cost.size
        pairs = []
        while cost.size and len(pairs) < limit and np.isfinite(cost).any():
            a, t = np.unravel_index(int(np.argmin(cost)), cost.shape)
            pairs.append((int(a), int(t)))
            cost[a, :] = np.inf
            cost[:, t] = np.inf
        return Allocation.centralized(problem, pairs)  # index pairs -> (agent id, task id)
'''

TEST = '''"""The simulator's own plugin checks (valid answers, no mutation, determinism, rng
use)."""

from dispatch.checks.allocators import check_allocator

from {pkg}.allocator import {cls}


def test_passes_the_plugin_checks():
    report = check_allocator({cls})
    assert report.ok, report


def test_passes_with_a_parameter():
    assert check_allocator({cls}, max_pairs=2).ok
'''

README = '''# dispatch-{dist}: the `{name}` allocator

An allocator plugin for the dispatch simulator (`dispatch-sim`), written by
`dispatch new allocator {name}`. The allocator is in `{pkg}/allocator.py`; `pyproject.toml`
registers it under the entry-point group `dispatch.allocators` as `{name}`.

```bash
pip install -e .                 # into the environment that has dispatch-sim
dispatch plugins                 # lists {name}
dispatch check {name}            # the simulator's checks on random problems
dispatch check {name} --param max_pairs=2
pytest tests                     # the same checks from pytest
```

In a scenario:

```toml
[dispatch]
allocator = "{name}"

[dispatch.allocator_params.{name}]   # optional: its constructor's keyword arguments
max_pairs = 2

[sweep]
allocator = ["hungarian", "{name}"]  # compare it with the built-ins
```
'''


def new_allocator(name: str, where: Path, *, overwrite: bool = False) -> Path:
    """Write the package ``where / dispatch-<name>`` (see the module docstring); returns its
    folder. Refuses a name that is not a lower-case identifier, or a folder that exists
    (unless ``overwrite``)."""
    if not NAME.match(name):
        raise DispatchError(f"allocator name {name!r}: use lower-case letters, digits and _ "
                            "(a Python identifier starting with a letter, at most 41 chars)")

    if name in available("allocator"):
        raise DispatchError(f"an allocator named {name!r} is installed already; pick another "
                            "name")
    dist = name.replace("_", "-")
    pkg = f"dispatch_{name}"
    cls = "".join(part.capitalize() for part in name.split("_")) + "Allocator"
    root = Path(where) / f"dispatch-{dist}"
    if root.exists() and not overwrite:
        raise DispatchError(f"{root} exists; remove it or use --overwrite to overwrite its files")
    fields = {"name": name, "dist": dist, "pkg": pkg, "cls": cls}
    files = {
        root / "pyproject.toml": PYPROJECT,
        root / pkg / "__init__.py": f'"""The {name} allocator plugin."""\n',
        root / pkg / "allocator.py": ALLOCATOR,
        root / "tests" / f"test_{name}.py": TEST,
        root / "README.md": README,
    }
    for path, text in files.items():
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(text.format(**fields), encoding="utf-8")
    return root
