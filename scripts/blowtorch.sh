#!/usr/bin/env bash
# The real blowtorch walk-around (67 DSLR photos of a brass blowtorch on a carpet; shared/testdata/real/blowtorch,
# not in this repository) as captures/blowtorch -- the photos linked, not copied -- and the pipeline on it with
# Snakemake, as a person would run their own capture: SfM poses, automatic masks, every 8th photo held out of
# training and evaluated on. Extra arguments go to snakemake (`-n` for the plan, `--cores 8`).
#   ORCA_BLOWTORCH=/path/to/blowtorch  the dataset folder (default: ../shared/testdata/real/blowtorch)
#   ORCA_BLOWTORCH_REFERENCE=1         also link the photographers' cameras (poses_bounds.npy) and object masks
#                                      in, which the poses and masks stages then use: training on its own
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
DATA="${ORCA_BLOWTORCH:-$ROOT/../shared/testdata/real/blowtorch}"
CAPTURE="$ROOT/captures/blowtorch"
if [ ! -d "$DATA/images" ]; then
    echo "[blowtorch] no dataset at $DATA (its images/ folder): set ORCA_BLOWTORCH to the blowtorch folder" >&2
    exit 2
fi
bash "$ROOT/scripts/setup.sh"
cd "$ROOT"
export PATH="${ORCA_VENV:-$ROOT/.venv}/bin:$PATH"
mkdir -p "$CAPTURE/images"
for photo in "$DATA"/images/*; do  # links: nothing copied, an existing capture's files left as they are
    [ -e "$CAPTURE/images/$(basename "$photo")" ] || ln -s "$(cd "$(dirname "$photo")" && pwd)/$(basename "$photo")" \
        "$CAPTURE/images/"
done
if [ -n "${ORCA_BLOWTORCH_REFERENCE:-}" ]; then
    mkdir -p "$CAPTURE/masks"
    for name in poses_bounds.npy all_image_names.txt; do
        [ -e "$CAPTURE/$name" ] || ln -s "$(cd "$DATA" && pwd)/$name" "$CAPTURE/"
    done
    for mask in "$DATA"/masks/*.png; do
        [ -e "$CAPTURE/masks/$(basename "$mask")" ] || ln -s "$(cd "$(dirname "$mask")" && pwd)/$(basename "$mask")" \
            "$CAPTURE/masks/"
    done
fi
if [ ! -f "$CAPTURE/capture.yaml" ]; then
    # what a person would write: photos held out for evaluation (Snakemake's preset is fast; decode shrinks the
    # 2120x1415 photos to its 1600-pixel working size by itself)
    printf 'train:\n  holdout_every: 8\n' > "$CAPTURE/capture.yaml"
fi
exec snakemake --cores "${ORCA_CORES:-2}" --config captures='["blowtorch"]' "$@"
