"""What README.md shows holds: its two first examples (one per world) run as written and print
what the code computes (the robot teams' costs are the golden summaries' seed-0 rows); the
excerpt of Table I that ``scripts/paper.sh`` prints is the golden summaries' mean and paired
gap; the run count it states is what the script's scenario expands to."""

from __future__ import annotations

import contextlib
import io
import re
import statistics

import pandas as pd
import pytest

from dispatch.scenario.load import load_scenario
from tests.conftest import ROOT

README = (ROOT / "README.md").read_text(encoding="utf-8")
GOLDEN = pd.read_csv(ROOT / "tests" / "data" / "golden_summaries.csv")


def _examples() -> list[str]:
    """The README's Python blocks, in order: the robot teams, then the taxis."""
    blocks = re.findall(r"```python\n(.*?)```", README, re.S)
    assert len(blocks) == 2, "the README shows one first example per world"
    return blocks


def _run(code: str, monkeypatch) -> tuple[str, dict]:
    """Execute a README block from the repository root (its paths are relative to it, as the
    README says); return what it printed and its variables."""
    monkeypatch.chdir(ROOT)
    scope: dict = {}
    out = io.StringIO()
    with contextlib.redirect_stdout(out):
        exec(compile(code, "README.md", "exec"), scope)  # noqa: S102 - the README's own code
    return out.getvalue(), scope


def _golden_static(n_agents: int) -> pd.DataFrame:
    g = GOLDEN[(GOLDEN["scenario"] == "paper_static") & (GOLDEN["n_agents"] == n_agents)]
    return g.pivot(index="seed", columns="allocator", values="total_cost")


def test_robot_example_prints_the_golden_costs(monkeypatch):
    printed, _ = _run(_examples()[0], monkeypatch)
    lines = printed.splitlines()
    assert [line.split()[0] for line in lines] == ["hungarian", "greedy", "magnnet"]
    golden = GOLDEN[(GOLDEN["scenario"] == "paper_static") & (GOLDEN["n_agents"] == 8)
                    & (GOLDEN["seed"] == 0)].set_index("allocator")
    for line in lines:
        m = re.fullmatch(r"(\w+) +cost +([\d.]+) s  conflict-free (\d+)%", line)
        assert m, line
        row = golden.loc[m.group(1)]
        assert float(m.group(2)) == pytest.approx(row["total_cost"], abs=0.05), line
        assert int(m.group(3)) == round(100 * row["conflict_free_rate"]), line


def test_taxi_example_runs_the_first_hour(monkeypatch):
    printed, scope = _run(_examples()[1], monkeypatch)
    s, tasks = scope["s"], scope["tasks"]
    assert s["n_agents"] == 300 and s["allocator"] == "hungarian"
    assert s["sim_time"] <= 3600.0
    counts = tasks["state"].value_counts().to_dict()
    assert sum(counts.values()) == len(tasks) == s["n_tasks"] > 0
    assert counts["completed"] == s["tasks_completed"] > 0
    assert 0 < s["empty_distance"] < s["distance"] and s["wait_time_mean"] > 0
    empty = s["empty_distance"] / s["distance"]
    assert printed.splitlines() == [
        str(counts), f"mean wait {s['wait_time_mean']:.0f} s, empty km {empty:.0%}"]


def test_paper_table_excerpt_is_the_golden_summaries():
    """Each row of the README's Table I excerpt: the mean total cost over the seeds and the gap
    to Hungarian paired by seed (the mean of the per-seed gaps), as ``dispatch run`` prints."""
    table = re.search(r"```text\n( allocator +N +runs +cost s +gap\n.*?)```", README, re.S)
    assert table, "the README shows the Table I excerpt that paper.sh prints"
    rows = table.group(1).splitlines()[1:]
    assert len(rows) == 4
    for row in rows:
        name, n, runs, cost, *gap = row.split()
        costs = _golden_static(int(n))
        assert int(runs) == costs[name].count() == 10, row
        assert float(cost) == pytest.approx(costs[name].mean(), abs=0.05), row
        if name == "hungarian":
            assert gap == [], row
            continue
        paired = statistics.fmean(costs[name] / costs["hungarian"] - 1)
        assert gap == [f"{round(100 * paired, 1) + 0.0:+.1f}%"], row


def test_paper_script_run_count():
    """'200 runs (5 allocators × 4 team sizes × 10 seeds)' and the closing line's count are
    what the scenario that ``scripts/paper.sh`` runs expands to."""
    script = (ROOT / "scripts" / "paper.sh").read_text(encoding="utf-8")
    (path,) = re.findall(r"dispatch run (scenarios/\S+\.toml)", script)
    sc = load_scenario(ROOT / path)
    m = re.search(r"(\d+) runs \((\d+) allocators × (\d+) team sizes × (\d+)\s+seeds\)",
                  README)
    assert m, "the README states the run count of paper.sh"
    total, allocators, sizes, seeds = map(int, m.groups())
    runs = sc.runs()
    assert len(runs) == total == allocators * sizes * seeds
    assert len({r.allocator for r in runs}) == allocators
    assert len({r.agents for r in runs}) == sizes
    assert len({r.seed for r in runs}) == seeds
    assert f"`{total} run(s) in " in README
