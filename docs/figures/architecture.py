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


#: the kernel's floors, top down: (sub-packages side by side, what they hold)
FLOORS = [
    (("run/",), "wiring of a run · runner and sweeps · plugins built · command line"),
    (("checks/", "scenario/"), "plugin checks · scaffold  |  TOML read once · --set · budget"),
    (("output/",), "Parquet recorder · rows · summary · printed tables"),
    (("fleet/",), "batteries · charger visits · repositioning · shifts · faults"),
    (("decide/",), "dispatcher · pipeline · costs · answers · meeting · offers · prebook"),
    (("space/",), "voxel world (PyBullet) · road network · congestion · drivers"),
    (("plan/",), "tasks · vehicles · stops and the schedule rule · operator"),
    (("config/",), "the typed configuration: data only"),
    (("api/",), "what a plugin author reads: problem · contracts · registry"),
    (("files/", "ground"), "trips · roads · tables  |  errors · locations · events"),
]


def house(ax):
    ax.set_title("The house: who imports whom", fontsize=11, weight="bold")
    ax.add_patch(Polygon([(0.06, 0.88), (0.5, 0.99), (0.94, 0.88)], fc=PURPLE, ec="#555555"))
    ax.text(0.5, 0.915, "analysis/  reports, figures, replay (reads Parquet only)",
            ha="center", va="center", fontsize=8)
    box(ax, 0.09, 0.815, 0.82, 0.045,
        "Parquet tables  summary · tasks · events · vehicles · ...", GREY, 8)
    names = ("allocators/", "planners/", "repositioners/", "chargers/", "acceptors/", "sizers/")
    for i, name in enumerate(names):
        box(ax, 0.09 + i * 0.142, 0.73, 0.112, 0.05, name, ORANGE, 7)
    ax.text(0.5, 0.695, "plugins: entry points, found by name; they import dispatch/api/",
            ha="center", fontsize=7, style="italic")
    ax.add_patch(FancyBboxPatch((0.06, 0.005), 0.88, 0.675,
                                boxstyle="round,pad=0.005,rounding_size=0.02",
                                fc="white", ec="#555555", lw=1))
    ax.text(0.5, 0.662, "dispatch/  the kernel in floors: each imports only floors below it",
            ha="center", va="center", fontsize=7.5, weight="bold")
    h, y = 0.0605, 0.645
    for names, what in FLOORS:
        y -= h
        color = GREEN if names == ("space/",) else BLUE
        w = 0.84 / len(names)
        for i, name in enumerate(names):
            part = what.split("  |  ")[i] if len(names) > 1 else what
            box(ax, 0.09 + i * w, y + 0.011, w - 0.03, h - 0.022, f"{name}  {part}", color, 6.8)


def flow(ax):
    ax.set_title("One request through a run", fontsize=11, weight="bold")
    steps = [
        ("scenario.toml  →  typed config, runs of its sweep", GREY),
        ("task source releases a request (trace, Poisson, static)", GREEN),
        ("dispatcher wakes (at once, or after the batch window)", BLUE),
        ("planner: cost of each idle (or pooling) vehicle × open request", ORANGE),
        ("allocator answers; the dispatcher checks the answer", ORANGE),
        ("vehicle drives its stop list: pickup, drop-off", BLUE),
        ("request closes: completed, rejected, expired, cut off", GREEN),
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
    fig, (a, b) = plt.subplots(1, 2, figsize=(12, 6.2))
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
