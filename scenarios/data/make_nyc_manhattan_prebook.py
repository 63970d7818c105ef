"""Make scenarios/data/nyc_manhattan_prebook{30,60}.csv: the NYC taxi requests of Sunday 2014-12-21
shipped with the package (dispatch/data/nyc_manhattan/nyc_taxi_2014-12-21_20k.csv, BSD 3-Clause:
its LICENSE.txt is copied beside them as nyc_manhattan_prebook_LICENSE.txt) with a ``booked_at``
column: 30 % (60 %) of the requests booked one hour before their departure, blank for the others.

Which requests are booked is synthesised (the records say nothing about bookings): request ``k``
draws ``u_k`` uniform in [0, 1) from ``numpy.random.default_rng(SEED)`` (one draw per row, in
the file's order) and is booked where ``u_k < share``, so the 30 % are a subset of the 60 %.
A booking an hour before a departure before 01:00 falls on the day before (the run enters it
at its start). Every other column is the source's, byte for byte.

Run: ``PYTHONPATH=. .venv/bin/python scenarios/data/make_nyc_manhattan_prebook.py``.
"""

from __future__ import annotations

import csv
import shutil
from datetime import datetime, timedelta
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
SRC = HERE.parents[1] / "dispatch" / "data" / "nyc_manhattan"
TRACE = SRC / "nyc_taxi_2014-12-21_20k.csv"
SEED = 20141221
LEAD = timedelta(hours=1)
SHARES = (30, 60)


def main() -> None:
    shutil.copy(SRC / "LICENSE.txt", HERE / "nyc_manhattan_prebook_LICENSE.txt")
    with TRACE.open(newline="") as f:
        rows = list(csv.reader(f))
    header, body = rows[0], rows[1:]
    col = header.index("departure_time")
    u = np.random.default_rng(SEED).random(len(body))
    for share in SHARES:
        out = HERE / f"nyc_manhattan_prebook{share}.csv"
        with out.open("w", newline="") as f:
            w = csv.writer(f, lineterminator="\n")
            w.writerow(header + ["booked_at"])
            for r, x in zip(body, u.tolist()):
                booked = ""
                if x < share / 100:
                    t = datetime.fromisoformat(r[col]) - LEAD
                    booked = t.strftime("%Y-%m-%d %H:%M:%S")
                w.writerow(r + [booked])
        print(f"{out.name}: {len(body)} requests, {int((u < share / 100).sum())} booked")


if __name__ == "__main__":
    main()
