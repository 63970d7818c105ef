"""The site's sources: every how-to is listed by both indexes, every page is in a toctree, and
no page speaks of the project's history (issue numbers, waves, targets met or not) instead of
what a figure measures."""

from __future__ import annotations

import re
from pathlib import Path

DOCS = Path(__file__).resolve().parents[2] / "docs"

#: words about the project's history, not the user's task
HISTORY = re.compile(r"\bissues? #?\d+|\bwaves?\b|\b(targets?|goals?)\b[^.]{0,60}\bmet\b|"
                     r"\bnot met\b|had no time limit yet|not analysed", re.IGNORECASE)


def pages(folder: str) -> set[str]:
    return {p.stem for p in (DOCS / folder).glob("*.md") if p.stem != "index"}


def toctree(index: Path) -> set[str]:
    text = index.read_text(encoding="utf-8")
    entries = set()
    for block in re.findall(r"```\{toctree\}\n(.*?)```", text, re.S):
        entries |= {ln.strip() for ln in block.splitlines()
                    if ln.strip() and not ln.strip().startswith(":")}
    return entries


def test_every_howto_is_in_both_indexes():
    howtos = pages("howto")
    assert howtos
    index = (DOCS / "howto" / "index.md").read_text(encoding="utf-8")
    assert toctree(DOCS / "howto" / "index.md") == howtos
    assert not [h for h in howtos if f"]({h}.md)" not in index]
    home = (DOCS / "index.md").read_text(encoding="utf-8")
    assert not [h for h in howtos if f"](howto/{h}.md)" not in home]


def test_every_explanation_page_is_in_a_toctree():
    assert toctree(DOCS / "explanation" / "index.md") == pages("explanation")


def test_no_page_speaks_of_the_projects_history():
    sources = [p for p in DOCS.rglob("*.md") if "_build" not in p.parts
               and "generated" not in p.parts and "jupyter_execute" not in p.parts]
    found = [f"{p.relative_to(DOCS)}: {m.group(0)!r}" for p in sources
             for m in HISTORY.finditer(p.read_text(encoding="utf-8"))]
    assert not found
