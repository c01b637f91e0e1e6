#!/usr/bin/env bash
# Set up (idempotent) and run the test suite. Extra arguments go to pytest, e.g. `scripts/test.sh -k decode`.
#
#   ORCA_TEST_WORKERS  pytest-xdist worker processes (default: the cores, at most 4; 0 runs in this process).
#                      Each test file runs whole in one worker, so its module fixtures are made once; the renders
#                      the files share are made once per run, and the longest files start first (tests/conftest.py).
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
bash "$ROOT/scripts/setup.sh"
cd "$ROOT"
# More than 4 workers would mostly add memory (the masks and training tests hold 1-2 GB each) for little time.
WORKERS="${ORCA_TEST_WORKERS:-$(( $(nproc) < 4 ? $(nproc) : 4 ))}"
exec "${ORCA_VENV:-$ROOT/.venv}/bin/python" -m pytest -n "$WORKERS" --dist loadfile --no-loadscope-reorder "$@"
