"""Numeric columns of trace and start files are read from Arrow buffers, as pyarrow would give
them, without importing pandas (a fifth of a second and tens of MB inside every trace run)."""

import subprocess
import sys
import textwrap

import numpy as np
import pyarrow as pa
import pytest

from dispatch.files.tables import numbers_of
from tests.dispatch.test_trips import road_scenario, write_csv

COLUMNS = [
    pa.chunked_array([], type=pa.float64()),
    pa.chunked_array([pa.array([1.5, -2.0, 3.25])]),
    pa.chunked_array([pa.array([1.0, 2.0]), pa.array([3.0])]),
    pa.chunked_array([pa.array([7, 8, 9, 10], pa.int32()).slice(1, 2)]),
    pa.chunked_array([pa.array([1, 2], pa.uint16()), pa.array([3], pa.uint16())]),
    pa.chunked_array([pa.array([1.0, None])]),  # nulls: pyarrow's own conversion
    pa.chunked_array([pa.array([True, False])]),
]


@pytest.mark.parametrize("col", COLUMNS, ids=lambda c: str(c.type))
def test_numbers_are_pyarrows_own(col):
    got, want = numbers_of(col), col.to_numpy()
    assert got.dtype == want.dtype
    np.testing.assert_array_equal(got, want)


def test_a_trace_run_reads_its_files_without_pandas(tmp_path):
    write_csv(tmp_path / "trips.csv", ["t", "origin_node", "dest_node"], [(0, 0, 5), (3.5, 7, 2)])
    write_csv(tmp_path / "fleet.csv", ["vehicle_id", "node"], [(0, 1), (1, 3)])
    path = road_scenario(tmp_path, tasks='source = "trace"\ntrace = "trips.csv"',
                         fleet='start = "fleet.csv"')
    code = textwrap.dedent(f"""\
        import sys
        from dispatch.run.runner import run_one
        from dispatch.scenario.load import load_scenario
        [spec] = load_scenario({str(path)!r}, ignore_limits=True).runs()
        result = run_one(spec, {str(tmp_path / "out")!r})
        assert int(result.summary["tasks_completed"]) == 2, result.summary
        print("pandas" in sys.modules)
        """)
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         cwd=tmp_path, check=False)
    assert out.returncode == 0, out.stderr[-2000:]
    assert out.stdout.strip().splitlines()[-1] == "False"
