"""Sphinx extension: the published bench boards as a page a reader can take in.

A board (``dispatch bench``'s ``bench.md`` and ``bench.csv``, published under
``howto/bench_board/``) holds two tables per instance, about 10,000 words for the full suite.
Before the build reads its sources this writes, for each board, a page to include
(``howto/generated/<name>.md``, git-ignored):

* one summary table per world, instances by allocators, of the board's headline figure
  (voxel world: the cost gap to ``hungarian``'s run of the same seed, the optimum on the static
  instances; road networks: the served share and the mean wait), the best of a row in bold;
* a status said once (``rtv``'s "unsupported" sentence) instead of in every instance's table;
* the board's per-instance tables unchanged, each folded in a ``<details>`` block.

Everything is read from the published files, so that a board remade by ``dispatch bench`` and
copied there is shown the same way; nothing here is copied by hand.
"""

from __future__ import annotations

import csv
import math
import re
from collections import defaultdict
from pathlib import Path

HERE = Path(__file__).resolve().parents[1]
OUT = HERE / "howto" / "generated"
#: (board folder under docs/howto, page written)
BOARDS = (("bench_board", "bench_board.md"), ("bench_board/variants", "bench_variants.md"))

#: the headline figure of each world: (column, heading, as text)
HEADLINE = {
    "voxel": ("gap", "gap to `hungarian` (%)", lambda v: _pct(v)),
    "road": ("served_share", "served (%)", lambda v: _pct(v)),
}


def _pct(share: float) -> str:
    """``share`` in per cent, one decimal, no ``-0.0``."""
    text = f"{100 * share:.1f}"
    return "0.0" if text == "-0.0" else text
WORLD_TITLE = {"voxel": "Voxel world (robot teams)", "road": "Road networks (taxis)"}


def _mean(values: list[float]) -> float:
    finite = [v for v in values if not math.isnan(v)]
    return sum(finite) / len(finite) if finite else math.nan


def _number(text: str) -> float:
    try:
        return float(text)
    except ValueError:
        return math.nan


def read_rows(path: Path) -> list[dict[str, str]]:
    with path.open(newline="", encoding="utf-8") as f:
        return list(csv.DictReader(f))


def short_status(status: str) -> str:
    """``ok``, ``timeout`` or ``unsupported``: the status's first word."""
    return status.split(":", 1)[0].strip()


def summary(rows: list[dict[str, str]]) -> tuple[list[str], dict[str, str]]:
    """``(lines, statuses)``: a Markdown table per world of the headline figure (mean over the
    seeds of the runs that finished), and each long status once, by its short word and the
    allocators it concerns."""
    order_alloc: list[str] = []
    order_inst: dict[str, list[str]] = defaultdict(list)
    cells: dict[tuple[str, str], list[dict[str, str]]] = defaultdict(list)
    long_status: dict[str, set[str]] = defaultdict(set)
    for r in rows:
        if r["allocator"] not in order_alloc:
            order_alloc.append(r["allocator"])
        if r["instance"] not in order_inst[r["world"]]:
            order_inst[r["world"]].append(r["instance"])
        cells[(r["instance"], r["allocator"])].append(r)
        if r["status"] != "ok":
            long_status[r["status"]].add(r["allocator"])
    lines = []
    for world, instances in order_inst.items():
        column, heading, fmt = HEADLINE[world]
        allocs = [a for a in order_alloc if any((i, a) in cells for i in instances)]
        lines += [f"**{WORLD_TITLE.get(world, world)}**: {heading}"
                  + (", and the mean wait (s) in brackets" if world == "road" else "")
                  + "; mean over the seeds.", "",
                  "| instance | " + " | ".join(f"`{a}`" for a in allocs) + " |",
                  "|---|" + "---:|" * len(allocs)]
        for inst in instances:
            means, texts = {}, {}
            for a in allocs:
                runs = cells.get((inst, a), [])
                ok = [r for r in runs if r["status"] == "ok"]
                if not ok:  # unsupported: "–", said once below the tables
                    word = short_status(runs[0]["status"]) if runs else ""
                    texts[a] = "–" if word == "unsupported" else word
                    continue
                means[a] = _mean([_number(r[column]) for r in ok])
                texts[a] = fmt(means[a]) if not math.isnan(means[a]) else "–"
                if world == "road":
                    wait = _mean([_number(r["wait_mean"]) for r in ok])
                    texts[a] += f" ({wait:.0f})" if not math.isnan(wait) else ""
            finite = {a: m for a, m in means.items() if not math.isnan(m)}
            if finite:
                best = (min if world == "voxel" else max)(finite.values())
                for a, m in finite.items():
                    if fmt(m) == fmt(best):
                        texts[a] = f"**{texts[a]}**"
            lines.append(f"| {inst} | " + " | ".join(texts[a] for a in allocs) + " |")
        lines.append("")
    notes = {}
    for status in long_status:
        word = short_status(status)
        if word == "unsupported":
            notes[status] = word
    return lines, notes


def fold_instances(text: str, notes: dict[str, str]) -> list[str]:
    """The board's per-instance sections, each folded under its name and description; long
    statuses in ``notes`` shortened to their word; the columns' glossary folded too."""
    for status, word in notes.items():
        text = text.replace(f"| {status} |", f"| {word} |")
    parts = re.split(r"^## ", text, flags=re.M)
    out = []
    for part in parts[1:]:
        title, _, body = part.partition("\n")
        body = body.strip("\n")
        first, _, rest = body.partition("\n\n")
        label = f"{title}: {first.strip()}" if title != "Columns" else "What each column means"
        out += ["<details>", f"<summary>{_html(label)}</summary>", "",
                (rest if title != "Columns" else body).strip("\n"), "", "</details>", ""]
    return out


def _html(text: str) -> str:
    text = text.replace("&", "&amp;").replace("<", "&lt;").replace(">", "&gt;")
    return re.sub(r"`([^`]+)`", r"<code>\1</code>", text)


def board_page(folder: Path) -> str:
    """The page of one published board (``folder`` holds its ``bench.md`` and ``bench.csv``)."""
    text = (folder / "bench.md").read_text(encoding="utf-8")
    rows = read_rows(folder / "bench.csv")
    head = re.split(r"^## ", text, maxsplit=1, flags=re.M)[0]
    head_lines = [ln for ln in head.splitlines() if not ln.startswith("# ")]
    lines, notes = summary(rows)
    said = []
    for status in notes:
        allocs = sorted({r["allocator"] for r in rows if r["status"] == status})
        instances = {r["instance"] for r in rows if r["status"] == status}
        worlds = {r["world"] for r in rows if r["instance"] in instances}
        whole = [w for w in worlds
                 if instances >= {r["instance"] for r in rows if r["world"] == w}]
        where = (f"every instance of the {WORLD_TITLE.get(whole[0], whole[0]).lower()}"
                 if len(whole) == 1 and len(worlds) == 1 else ", ".join(sorted(instances)))
        said.append(f"`{'`, `'.join(allocs)}` is unsupported on {where} (\"–\" above, "
                    f"`unsupported` in the tables below): {status.split(':', 1)[1].strip()}.")
    out = [*lines, *said, ""]
    out += ["How the board was made (the head of its `bench.md`):", "",
            *[f"- {ln}" for ln in head_lines if ln.strip()], "",
            "Per instance, every figure of the board (click to open):", ""]
    out += fold_instances(text, notes)
    return "\n".join(out) + "\n"


def generate(app=None) -> None:
    OUT.mkdir(parents=True, exist_ok=True)
    for folder, name in BOARDS:
        text = board_page(HERE / "howto" / folder)
        path = OUT / name
        if not path.exists() or path.read_text(encoding="utf-8") != text:
            path.write_text(text, encoding="utf-8")  # unchanged pages keep Sphinx's cache


def setup(app):
    app.connect("builder-inited", generate)
    return {"version": "1", "parallel_read_safe": True}
