#!/usr/bin/env bash
# Set up (idempotent) and run the pipeline on the bundled demo capture with Snakemake.
# Extra arguments go to snakemake, e.g. `scripts/demo.sh -n` to show the plan, `--cores 8` for more cores.
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
bash "$ROOT/scripts/setup.sh"
cd "$ROOT"
export PATH="${ORCA_VENV:-$ROOT/.venv}/bin:$PATH"
exec snakemake --cores "${ORCA_CORES:-2}" --config captures='["demo"]' "$@"
