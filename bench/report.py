"""``bench.md`` (a leaderboard per instance: mean ± 95 % half-width over seeds, the best mean of
each column in bold, then the paired differences against hungarian) and ``bench.png`` (one
summary picture)."""

from __future__ import annotations

import math
from pathlib import Path

from bench.metrics import BOARD, DESCRIPTIONS, LOWER_IS_BETTER, NOT_RANKED
from bench.stats import Interval, intervals, paired_differences
from bench.suite import REFERENCE, SUITE, VERSION

_BY_NAME = {i.name: i for i in SUITE}


def _fmt(v: float) -> str:
    if math.isnan(v):
        return "–"
    a = abs(v)
    if a == 0 or 0.01 <= a < 1e5:
        return f"{v:.3g}" if a < 100 else f"{v:.0f}"
    return f"{v:.2e}"


def _cell(iv: Interval) -> str:
    if math.isnan(iv.mean):
        return "–"
    return _fmt(iv.mean) + ("" if math.isnan(iv.half) else f" ± {_fmt(iv.half)}")


def _group(instance: str, rows: list[dict]) -> str:
    """The instance's group in the suite; an instance outside it: robots in a voxel world."""
    inst = _BY_NAME.get(instance)
    if inst is not None:
        return inst.group
    world = next((r["world"] for r in rows if r["instance"] == instance), "voxel")
    return "robots" if world == "voxel" else "fleets"


def _columns(instance: str, rows: list[dict]) -> list[str]:
    world = next((r["world"] for r in rows if r["instance"] == instance), "voxel")
    cols = list(BOARD[_group(instance, rows)])
    if world == "road":
        cols += [c for c in BOARD["fleets"] if c not in cols]
    return cols


def _ordered(rows: list[dict]) -> list[tuple[str, list[str]]]:
    seen: dict[str, list[str]] = {}
    for r in rows:
        allocs = seen.setdefault(r["instance"], [])
        if r["allocator"] not in allocs:
            allocs.append(r["allocator"])
    return list(seen.items())


def write_markdown(rows: list[dict], path: Path, machine: dict, seconds: float) -> None:
    """``bench.md`` of ``rows`` (see the module docstring)."""
    ivs, diffs = intervals(rows), paired_differences(rows)
    v = machine.get("versions", {})
    lines = [f"# Allocator bench {VERSION}" + (" (quick)" if machine.get("quick") else ""),
             "",
             f"Allocators: {', '.join(machine.get('allocators', [])) or '(baselines only)'}"
             + (f"; parameters {machine['params']}" if machine.get("params") else "")
             + f"; suite {machine.get('which', 'all')}"
             + (f", instances {', '.join(machine['only'])} only" if machine.get("only") else "")
             + (f"; a run stopped after {machine['time_limit_s'] / 60:g} min of wall time"
                if machine.get("time_limit_s") else "") + ".",
             f"Machine: {machine.get('cores')} cores ({machine.get('processor')}), "
             f"Python {machine.get('python')}, {machine.get('platform')}; load "
             f"{machine.get('load_1min_at_start', math.nan):.1f} at start; "
             + ", ".join(f"{k} {x}" for k, x in v.items()) + ".",
             f"Wall time of this call: {seconds:.0f} s on {machine.get('workers')} "
             f"{'Ray CPUs' if machine.get('ray') else 'worker processes'} "
             "(runs already finished in the folder are reused).",
             "",
             "Cells: mean ± half-width of the 95 % Student-t interval over the seeds; **bold**: "
             "the best mean of the column. Δ tables: the paired difference to hungarian "
             "(same seed), mean ± half-width; `*` where the interval excludes 0.",
             ""]
    for instance, allocs in _ordered(rows):
        inst = _BY_NAME.get(instance)
        cols = [c for c in _columns(instance, rows)
                if any(not math.isnan(ivs[(instance, a, c)].mean) for a in allocs)]
        mine = [r for r in rows if r["instance"] == instance]
        seeds = sorted({r["seed"] for r in mine})
        lines += [f"## {instance}", "",
                  f"{inst.note if inst else ''} ({mine[0]['world']}; seeds "
                  f"{', '.join(map(str, seeds))}; "
                  f"{_fmt(ivs[(instance, allocs[0], 'requests')].mean)} requests).", ""]
        best = {}
        for c in cols:
            if c in NOT_RANKED:
                continue
            means = [ivs[(instance, a, c)].mean for a in allocs]
            means = [m for m in means if not math.isnan(m)]
            if len(means) > 1:
                best[c] = min(means) if c in LOWER_IS_BETTER else max(means)
        lines.append("| allocator | " + " | ".join(cols) + " | status |")
        lines.append("|---|" + "---|" * (len(cols) + 1))
        for a in allocs:
            status = sorted({r["status"] for r in mine if r["allocator"] == a})
            cells = []
            for c in cols:
                iv = ivs[(instance, a, c)]
                s = _cell(iv)
                cells.append(f"**{s}**" if c in best and iv.mean == best[c] else s)
            lines.append(f"| {a} | " + " | ".join(cells) + " | "
                         + "; ".join(s.replace("|", "/") for s in status) + " |")
        others = [a for a in allocs if a != REFERENCE]
        if others and any(r["allocator"] == REFERENCE and r["status"] == "ok" for r in mine):
            dcols = [c for c in cols if c != "gap"]
            lines += ["", f"Δ vs {REFERENCE}:", "",
                      "| allocator | " + " | ".join(dcols) + " |",
                      "|---|" + "---|" * len(dcols)]
            for a in others:
                cells = []
                for c in dcols:
                    d = diffs[(instance, a, c)]
                    star = ("*" if not math.isnan(d.half) and abs(d.mean) > d.half else "")
                    cells.append(_cell(d) + star)
                lines.append(f"| {a} | " + " | ".join(cells) + " |")
        lines.append("")
    lines += ["## Columns", ""] + [f"- `{k}`: {t}" for k, t in DESCRIPTIONS.items()] + [""]
    path.write_text("\n".join(lines), encoding="utf-8")


def write_figure(rows: list[dict], path: Path) -> bool:
    """``bench.png``: per instance and allocator, robots' gap to hungarian and fleets' served
    share (top), and wall ms per decision (bottom, log scale); error bars the 95 % intervals.
    False (nothing drawn) without matplotlib."""
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        return False
    ivs = intervals(rows)
    order = _ordered(rows)
    allocs: list[str] = []
    for _, a in order:
        allocs += [x for x in a if x not in allocs]
    panels = [("robots", "gap", "gap to hungarian (%)", 100.0, False),
              ("fleets", "served_share", "served share (%)", 100.0, False),
              ("robots", "ms_per_decision", "ms per decision", 1.0, True),
              ("fleets", "ms_per_decision", "ms per decision", 1.0, True)]
    fig, axes = plt.subplots(2, 2, figsize=(13, 8), squeeze=False)
    colors = plt.get_cmap("tab10")
    for ax, (group, metric, label, scale, log) in zip(axes.T.flat, panels):
        names = [i for i, _ in order if _group(i, rows) == group]
        if not names:
            ax.set_visible(False)
            continue
        width = 0.8 / len(allocs)
        for k, a in enumerate(allocs):
            xs, ys, es = [], [], []
            for j, inst in enumerate(names):
                iv = ivs.get((inst, a, metric))
                if iv is None or math.isnan(iv.mean):
                    continue
                xs.append(j - 0.4 + width * (k + 0.5))
                ys.append(iv.mean * scale)
                es.append(0.0 if math.isnan(iv.half) else iv.half * scale)
            if xs:
                ax.bar(xs, ys, width, yerr=es, label=a, color=colors(k % 10), capsize=2)
        ax.set_xticks(range(len(names)), names, rotation=30, ha="right", fontsize=8)
        ax.set_ylabel(label)
        ax.set_title(f"{group}: {label}", fontsize=10)
        if log:
            ax.set_yscale("log")
        ax.grid(axis="y", alpha=0.3)
    handles, labels = [], []
    for ax in axes.flat:
        for h, lab in zip(*ax.get_legend_handles_labels()):
            if lab not in labels:
                handles.append(h)
                labels.append(lab)
    fig.suptitle(f"{VERSION}: mean over seeds, 95 % intervals", y=0.99, fontsize=11)
    fig.legend(handles, labels, loc="upper center", bbox_to_anchor=(0.5, 0.955),
               ncol=len(labels), frameon=False)
    fig.tight_layout(rect=(0, 0, 1, 0.91))
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return True
