"""A map by hour of what a learned value holds: one panel per chosen hour, each zone a square
coloured by ``V(zone, hour)`` (requests a vehicle there will still serve, discounted), the
network's nodes in grey beneath, cropped to where the value is above 2 % of its top; a
shared-ride value at ``--seats`` free seats (default: its most; after a decision a vehicle
holds at least the request it took, so an empty vehicle's class is only learned at the start).

Run: ``PYTHONPATH=. python benchmarks/value_map.py learning/data/values/FILE.npz --hours 3 8 12
17 21 --out docs/lookahead/FILE.png``.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))


def draw(path: Path, hours: list[float], out: Path, title: str | None = None,
         seats: int | None = None) -> None:
    """Write the map of the value file ``path`` at ``hours`` (of the day) to ``out`` (PNG), a
    shared-ride value at ``seats`` free seats (None: its most)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.collections import PatchCollection
    from matplotlib.patches import Rectangle

    from learning.value import ZoneValue

    v = ZoneValue.load(path)
    z = v.zones
    vals = np.stack([v.of_zone(np.arange(z.n), np.full(z.n, h * 3600.0 + 1.0), seats)
                     for h in hours])
    top = float(vals.max()) or 1.0
    fig, axes = plt.subplots(1, len(hours), figsize=(3.1 * len(hours), 3.6), squeeze=False)
    xy = (v.node_xy - v.node_xy.min(axis=0)) / 1000.0
    lo = z.centres - z.origin - z.size / 2
    # the panels show where the value lives (zones above 2 % of the top, 3 km around them):
    # a regional network's far suburbs are worth nothing and would shrink the city to a dot
    live = lo[vals.max(axis=0) > 0.02 * top] / 1000.0
    x0, y0 = live.min(axis=0) - 3.0
    x1, y1 = live.max(axis=0) + z.size / 1000.0 + 3.0
    for ax, h, row in zip(axes[0], hours, vals):
        ax.scatter(xy[:, 0], xy[:, 1], s=0.2, c="0.8", rasterized=True)
        boxes = [Rectangle((x / 1000.0, y / 1000.0), z.size / 1000.0, z.size / 1000.0)
                 for x, y in lo]
        pc = PatchCollection(boxes, cmap="viridis", alpha=0.85)
        pc.set_array(row)
        pc.set_clim(0.0, top)
        ax.add_collection(pc)
        ax.set_title(f"{int(h):02d}:{round(60 * (h % 1)):02d}")
        ax.set_xlim(x0, x1)
        ax.set_ylim(y0, y1)
        ax.set_aspect("equal")
        ax.set_xticks([])
        ax.set_yticks([])
    fig.colorbar(pc, ax=axes[0].tolist(), shrink=0.8,
                 label="value (discounted requests still served)")
    fig.suptitle(title or f"{path.name}: V(zone, hour), {z.size / 1000:g} km zones", y=1.04)
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=110, bbox_inches="tight")
    plt.close(fig)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("value", type=Path)
    p.add_argument("--hours", type=float, nargs="+", default=[3, 8, 12, 17, 21])
    p.add_argument("--out", type=Path, required=True)
    p.add_argument("--title", default=None)
    p.add_argument("--seats", type=int, default=None,
                   help="free seats of a shared-ride value's class (default: the most)")
    a = p.parse_args(argv)
    draw(a.value, a.hours, a.out, a.title, a.seats)
    return 0


if __name__ == "__main__":
    sys.exit(main())
