"""Draws docs/figures/architecture.png: the project as a house (left) and the flow of one
request through a run (right). Run: python docs/figures/architecture.py"""

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
from matplotlib.patches import FancyArrowPatch, FancyBboxPatch, Polygon  # noqa: E402

OUT = Path(__file__).with_suffix(".png")
BLUE, GREEN, ORANGE, GREY, PURPLE = "#dbe9f6", "#dff2df", "#fde7cf", "#eeeeee", "#eadff5"


def box(ax, x, y, w, h, text, color, size=9, weight="normal"):
    ax.add_patch(FancyBboxPatch((x, y), w, h, boxstyle="round,pad=0.01,rounding_size=0.02",
                                fc=color, ec="#555555", lw=1))
    ax.text(x + w / 2, y + h / 2, text, ha="center", va="center", fontsize=size,
            weight=weight, wrap=True)


def arrow(ax, a, b, text=None):
    ax.add_patch(FancyArrowPatch(a, b, arrowstyle="-|>", mutation_scale=12, color="#444444",
                                 lw=1.2))
    if text:
        ax.text((a[0] + b[0]) / 2 + 0.01, (a[1] + b[1]) / 2, text, fontsize=7.5,
                va="center", color="#333333")


def house(ax):
    ax.set_title("The house: who imports whom", fontsize=11, weight="bold")
    ax.add_patch(Polygon([(0.06, 0.80), (0.5, 0.98), (0.94, 0.80)], fc=PURPLE, ec="#555555"))
    ax.text(0.5, 0.855, "analysis/  reports, figures, animations\n(reads the Parquet files only)",
            ha="center", va="center", fontsize=8.5)
    box(ax, 0.08, 0.66, 0.84, 0.12, "Parquet tables  summary · tasks · events · vehicles ·\n"
        "decisions · assignments · chargers · soc", GREY, 8.5)
    for i, (name, what) in enumerate((("allocators/", "who serves\nwhich request"),
                                      ("planners/", "paths and\ntravel times"),
                                      ("repositioners/", "where idle\nvehicles go"),
                                      ("chargers/", "when cars\ncharge"))):
        box(ax, 0.08 + i * 0.215, 0.44, 0.195, 0.19, f"{name}\n{what}", ORANGE, 8)
    ax.text(0.5, 0.405, "plugins: entry points, found by name", ha="center", fontsize=7.5,
            style="italic")
    box(ax, 0.08, 0.18, 0.84, 0.2, "dispatch/  the kernel (imports no plugin)\n"
        "SimPy events · task book · dispatcher · vehicles and stop lists\n"
        "typed scenario config · recorder · command line", BLUE, 8.5, "bold")
    box(ax, 0.08, 0.04, 0.40, 0.11, "voxel world\n(drones, robots; PyBullet)", GREEN, 8)
    box(ax, 0.52, 0.04, 0.40, 0.11, "road network\n(OSMnx, TNTP, grid; taxis)", GREEN, 8)
    ax.text(0.5, 0.005, "spaces", ha="center", fontsize=7.5, style="italic")


def flow(ax):
    ax.set_title("One request through a run", fontsize=11, weight="bold")
    steps = [
        ("scenario.toml  →  typed config, runs of its sweep", GREY),
        ("task source releases a request (trace, Poisson, static)", GREEN),
        ("dispatcher wakes (at once, or after the batch window)", BLUE),
        ("planner: cost of each idle (or pooling) vehicle × open request", ORANGE),
        ("allocator answers; the dispatcher checks the answer", ORANGE),
        ("vehicle drives its stop list: pickup, drop-off", BLUE),
        ("request closes: completed, rejected, expired, cancelled", GREEN),
        ("its row is written to Parquet; the summary adds it up", GREY),
    ]
    h, gap = 0.074, 0.046
    y = 0.93
    for i, (text, color) in enumerate(steps):
        box(ax, 0.05, y - h, 0.9, h, text, color, 8.5)
        if i < len(steps) - 1:
            arrow(ax, (0.5, y - h), (0.5, y - h - gap))
        y -= h + gap


def main() -> None:
    fig, (a, b) = plt.subplots(1, 2, figsize=(11, 5.2))
    for ax in (a, b):
        ax.set_xlim(0, 1)
        ax.set_ylim(0, 1)
        ax.axis("off")
    house(a)
    flow(b)
    fig.tight_layout()
    fig.savefig(OUT, dpi=110)
    print(OUT)


if __name__ == "__main__":
    main()
