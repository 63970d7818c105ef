"""The bench board's page (``docs/_ext/bench_pages.py``) made from the published board: a
summary table per world on top, each long status said once, every instance's tables folded
below. Read without Sphinx."""

from __future__ import annotations

import csv
import importlib.util
import re
from pathlib import Path

import pytest

DOCS = Path(__file__).resolve().parents[2] / "docs"
BOARD = DOCS / "howto" / "bench_board"


@pytest.fixture(scope="module")
def pages():
    spec = importlib.util.spec_from_file_location("bench_pages", DOCS / "_ext" / "bench_pages.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.fixture(scope="module")
def rows():
    with (BOARD / "bench.csv").open(newline="", encoding="utf-8") as f:
        return list(csv.DictReader(f))


@pytest.fixture(scope="module")
def page(pages):
    return pages.board_page(BOARD)


def test_a_summary_table_per_world_with_every_instance(page, rows):
    top = page.split("<details>", 1)[0]
    worlds = {r["world"] for r in rows}
    assert top.count("| instance |") == len(worlds)
    for inst in {r["instance"] for r in rows}:
        assert re.search(rf"^\| {inst} \|", top, re.M), inst


def test_summary_cells_are_the_mean_over_the_seeds(page, rows):
    """An independent mean: the served share of one road instance and allocator."""
    served = [float(r["served_share"]) for r in rows
              if (r["instance"], r["allocator"], r["status"]) == ("nyc_1seat", "hungarian", "ok")]
    assert served
    line = re.search(r"^\| nyc_1seat \|.*$", page, re.M).group(0)
    first = line.split("|")[2].strip().strip("*")  # hungarian is the first allocator column
    assert first.startswith(f"{100 * sum(served) / len(served):.1f} (")


def test_a_long_status_is_said_once(page, rows):
    long = {r["status"] for r in rows if r["status"].startswith("unsupported:")}
    assert long  # the published board has rtv's on the voxel instances
    for status in long:
        reason = status.split(":", 1)[1].strip()
        assert page.count(reason) == 1


def test_every_instance_is_folded_below(page, rows):
    folded = re.findall(r"<details>\n<summary>([^<:]+)", page)
    assert set(folded) >= {r["instance"] for r in rows}
    assert page.count("<details>") == page.count("</details>")
    assert "\n## " not in page  # no heading inside a fold
