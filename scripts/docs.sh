#!/usr/bin/env bash
# Sets up the project (scripts/setup.sh), installs the docs extra and builds the site into
# docs/_build/html with warnings as errors; the tutorials run on every build.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
stamp=.venv/.docs-$(sha1sum pyproject.toml | cut -c1-16)
if [ ! -f "$stamp" ]; then
    echo "docs: installing the docs extra (sphinx, furo, myst-nb) ..."
    PYTHONWARNINGS=ignore .venv/bin/python -m pip install -q -e ".[docs]" 2>&1 \
        | grep -vE "is ignored|^\s*$" || true
    rm -f .venv/.docs-*
    touch "$stamp"
fi
echo "docs: building docs/_build/html (the tutorials run: a few minutes) ..."
start=$(date +%s)
.venv/bin/python -m sphinx -W --keep-going -q -b html docs docs/_build/html "$@"
echo "docs: built docs/_build/html/index.html in $(( $(date +%s) - start )) s"
