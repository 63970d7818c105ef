"""rtv with and without ``reorder`` on the NYC study's setting (issue 20): the same day, seats,
fleet and seed, the plan's stops kept in their order (``reorder = false``, the default) or
reordered with the new ones (``reorder = true``, Alonso-Mora et al.'s whole-trip routing).

Prints per setting the served share, mean wait, mean delay (drop-off - release - direct
drive), occupancy, vehicle-km, seconds per batch and what the bounds cut, and writes them to
``<out>/reorder.md`` and ``<out>/reorder.jsonl``.

Run: ``PYTHONPATH=. .venv/bin/python benchmarks/rtv_reorder.py --seats 4 --fleet 450 --seed 0``
(``--hours 6`` for a quick look).
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from benchmarks.nyc_study import run, run_arguments  # noqa: E402


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--out", default="runs/rtv_reorder")
    p.add_argument("--seats", type=int, default=4)
    p.add_argument("--fleet", type=int, default=450)
    p.add_argument("--seed", type=int, default=0)
    run_arguments(p)
    p.add_argument("--reorder", nargs="+", default=["false", "true"], choices=["false", "true"])
    a = p.parse_args(argv)
    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    rows = []
    lines = [f"Manhattan 2014-12-21, {a.hours:g} h, {a.seats} seats, {a.fleet} taxis, seed "
             f"{a.seed}, max_wait {a.max_wait:g} s, max_delay {a.max_delay:g} s, rtv batched 30 s",
             "", "| reorder | served % | mean wait s | mean delay s | occupancy | vehicle-km | "
             "s / batch | routes reordered / with several requests | cut (pairs / groups / orders / levels) |",
             "|---|---:|---:|---:|---:|---:|---:|---:|---|"]
    for flag in a.reorder:
        r = run(a, a.seats, "rtv", a.fleet, a.seed, params={"reorder": flag == "true"})
        r["reorder"] = flag == "true"
        rows.append(r)
        with open(out / "reorder.jsonl", "a") as f:
            f.write(json.dumps(r, default=float) + "\n")
        st = r["rtv"]
        lines.append(f"| {flag} | {100 * r['served']:.2f} | {r['wait']:.1f} | {r['delay']:.1f} | "
                     f"{r['occupancy']:.3f} | {r['vkm']:.0f} | {r['batch_s']:.3f} | "
                     f"{st.get('reordered', '-')} / {st.get('multi', 0)} | "
                     f"{st.get('pairs_cut', 0)} / {st.get('groups_cut', 0)} / "
                     f"{st.get('orders_cut', 0)} / {st.get('levels_cut', 0)} |")
        print(lines[-1], flush=True)
    text = "\n".join(lines) + "\n"
    (out / "reorder.md").write_text(text)
    print(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
