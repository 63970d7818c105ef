"""A test that skips says why in words a user can act on (``pytest -rs``, on in pyproject's
addopts as ``-ra``): the raw data of ``../shared/data`` named with its path and as not shipped."""

from __future__ import annotations

import subprocess
import sys

from tests.conftest import ROOT


def test_a_skip_for_missing_raw_data_names_the_path_and_says_it_is_not_shipped(tmp_path):
    missing = tmp_path / "shared" / "data" / "nothing.csv"
    (tmp_path / "none.ini").write_text("[pytest]\n")  # not the project's addopts and conftest
    (tmp_path / "test_needs_data.py").write_text(
        "import pytest\n"
        "from tests.conftest import missing_data\n"
        f"@pytest.mark.skipif(True, reason=missing_data({str(missing)!r}, 'a raw sample'))\n"
        "def test_x():\n"
        "    pass\n")
    out = subprocess.run([sys.executable, "-m", "pytest", "-rs", "-q", "-p", "no:cacheprovider",
                          "--noconftest", "-c", str(tmp_path / "none.ini"),
                          str(tmp_path / "test_needs_data.py")], cwd=tmp_path, capture_output=True,
                         text=True, timeout=120, env={"PYTHONPATH": str(ROOT), "COLUMNS": "300",
                                                       "PATH": "/usr/bin:/bin"})
    assert "1 skipped" in out.stdout, out.stdout + out.stderr
    line = next(s for s in out.stdout.splitlines() if s.startswith("SKIPPED"))
    assert f"needs a raw sample at {missing}" in line
    assert "not shipped with the repository" in line and "nothing to install" in line
