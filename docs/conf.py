"""Sphinx configuration of the dispatch site (built by ``bash scripts/docs.sh``)."""

import atexit
import logging
import os
import shutil
import sys
import tempfile
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent))  # the project, for autodoc and the generated reference
sys.path.insert(0, str(HERE / "_ext"))

# The tutorials' kernels read their configuration from a private IPython directory: the
# build's own (_ext/ipython_kernel_config.py: ipykernel's notice that the local TCP link to
# Sphinx is unencrypted, once per kernel, left out), not the user's profile.
_IPYTHONDIR = Path(tempfile.mkdtemp(prefix="dispatch-docs-ipython-"))
(_IPYTHONDIR / "profile_default").mkdir()
shutil.copy(HERE / "_ext" / "ipython_kernel_config.py", _IPYTHONDIR / "profile_default")
os.environ["IPYTHONDIR"] = str(_IPYTHONDIR)
atexit.register(shutil.rmtree, _IPYTHONDIR, ignore_errors=True)


def _keep_root_logging() -> None:
    """accessible-pygments (furo's dependency; its styles load with every Pygments style)
    calls ``logging.basicConfig(level=INFO)`` on import, which printed an INFO line of
    nbclient's per tutorial into the build's output. Import it now and put the root logger
    back as Python sets it (no handler, level WARNING): warnings still reach stderr."""
    root = logging.getLogger()
    handlers, level = list(root.handlers), root.level
    try:
        import a11y_pygments  # noqa: F401
    except ImportError:
        return
    for h in root.handlers[:]:
        if h not in handlers:
            root.removeHandler(h)
    root.setLevel(level)


_keep_root_logging()

project = "dispatch"
author = "the dispatch authors"
copyright = "the dispatch authors, MIT licence"

extensions = [
    "myst_nb",  # MyST Markdown, and the tutorials executed as notebooks on every build
    "sphinx.ext.autodoc",
    "sphinx.ext.napoleon",
    "dispatch_reference",  # writes reference/generated/ from the code before reading
    "bench_pages",  # writes howto/generated/ from the published bench boards
]

html_theme = "furo"
html_title = "dispatch"

myst_enable_extensions = ["colon_fence", "dollarmath"]
myst_heading_anchors = 3
suppress_warnings = ["myst.header"]  # moved study pages keep their own heading depth

# Every tutorial runs start to end on every build; an error in one fails the build.
nb_execution_mode = "force"
nb_execution_timeout = 600
nb_execution_raise_on_error = True
nb_execution_show_tb = True
nb_merge_streams = True

exclude_patterns = [
    "_build",
    "README.md",
    # study outputs written by the benchmarks; their pages include them
    "nyc_study/*.md",
    "lookahead/README.md",
    # the published bench boards (dispatch bench's bench.md), included by howto/bench_board.md
    "howto/bench_board/*.md",
    "howto/bench_board/variants/*.md",
    # the boards' pages (bench_pages), included by howto/bench_board.md
    "howto/generated/*.md",
]

autodoc_member_order = "bysource"
autodoc_typehints = "description"
autodoc_default_options = {"members": True, "show-inheritance": True}
napoleon_google_docstring = True
napoleon_numpy_docstring = False
