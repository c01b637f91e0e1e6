#!/usr/bin/env bash
# Set up (idempotent), render the demo capture on first use, and run the pipeline on it with Snakemake.
# Extra arguments go to snakemake, e.g. `scripts/demo.sh -n` to show the plan, `--cores 8` for more cores.
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
bash "$ROOT/scripts/setup.sh"
cd "$ROOT"
export PATH="${ORCA_VENV:-$ROOT/.venv}/bin:$PATH"
if [ ! -f captures/demo/ground_truth/scene.json ]; then
    echo "[demo] rendering the demo capture captures/demo (once; about 4 minutes on 2 cores)" >&2
    orca synth sphere captures/demo --overwrite
fi
exec snakemake --cores "${ORCA_CORES:-2}" --config captures='["demo"]' "$@"
