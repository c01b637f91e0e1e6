"""What a RAW photo records around its saturated photosites, against the ground truth of a synthetic capture:
are the pixels next to a clipped highlight lower bounds (as training takes a clipped pixel) or measurements?

    python bench/clipped_ring.py captures/demo                 # every photo of an `orca synth` capture
    python bench/clipped_ring.py captures/demo --every 3

Each photo is decoded as `orca decode` does (:func:`pipeline.raw.decode_raw`, the first photo's as-shot white
balance) with the clipped mask grown by 0, 1 and 2 raw pixels. The pixels are sorted into the mask itself (the
saturated photosites and those between them) and the rings that growing it adds; per ring and channel, the
median and the 10th / 90th percentiles of log(decoded / true) over the ring's pixels. A lower bound is a
ring whose decoded values fall below the truth (negative log ratios); a measurement one centred on zero.
Training's evidence for ``decode.clip_dilate_raw`` (docs/method.md). Prints a table and appends a JSON line to
bench/results/clipped_ring.jsonl.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from bench.blowtorch import append_record, commit, machine  # noqa: E402
from pipeline.ground_truth import resolve_ground_truth  # noqa: E402
from pipeline.raw import decode_raw, probe  # noqa: E402

RADII = (0, 1, 2, 5)  # the last ring, 3-5 pixels out, is the control: pixels demosaicing reads no clipped photosite for
RESULTS = ROOT / "bench" / "results" / "clipped_ring.jsonl"


def ring_log_ratios(photos: list[Path], truth_of, white_balance) -> dict[str, np.ndarray]:
    """``{ring: (N, 3) log(decoded / true)}`` over the photos' unsaturated pixels (truth below the white level
    in every channel) of each ring around the clipped mask: ``mask`` (radius 0) and ``ring a-b`` (the pixels
    growing it from a - 1 to b raw pixels adds)."""
    rings: dict[str, list[np.ndarray]] = {}
    for path in photos:
        info, masks, linear = probe(path), {}, None
        for r in RADII:
            decoded = decode_raw(info, white_balance=white_balance, clip_dilate=r)
            masks[r], linear = decoded.clipped, decoded.linear
        truth = truth_of(path.stem)
        for inner, r in zip((None, *RADII), RADII):
            ring = masks[r] & ~masks[inner] if r else masks[0]
            pick = ring & (truth.max(-1) < 1.0)
            ratio = np.log(np.maximum(linear[pick], 1e-4) / np.maximum(truth[pick], 1e-4))
            name = "mask" if r == 0 else f"ring {r}" if r == inner + 1 else f"ring {inner + 1}-{r}"
            rings.setdefault(name, []).append(ratio)
    return {k: np.concatenate(v) for k, v in rings.items()}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("capture", type=Path, help="an `orca synth` capture folder (DNG photos + ground_truth/)")
    ap.add_argument("--every", type=int, default=1, help="every k-th photo")
    args = ap.parse_args()
    gt = resolve_ground_truth(args.capture)
    photos = sorted(args.capture.glob("*.dng"))[:: args.every]
    if not photos:
        raise SystemExit(f"no DNG photos in {args.capture}")
    white_balance = probe(photos[0]).as_shot_wb
    if white_balance is None:
        raise SystemExit(f"{photos[0]} records no as-shot white balance")
    rings = ring_log_ratios(photos, lambda name: gt.exr("linear", f"{name}.exr")[..., :3] * gt.factor,
                            white_balance)
    figures = {}
    print(f"{'':>10} {'pixels':>7}  log(decoded / true) R G B: median / 10th / 90th percentile")
    for name, v in rings.items():
        figures[name] = {"pixels": len(v), "median": np.median(v, 0).round(3).tolist(),
                         "p10": np.percentile(v, 10, 0).round(3).tolist(),
                         "p90": np.percentile(v, 90, 0).round(3).tolist()} if len(v) else {"pixels": 0}
        f = figures[name]
        cells = ["(" + " ".join(f"{x:+.2f}" for x in f[k]) + ")" for k in ("median", "p10", "p90")] if len(v) else []
        print(f"{name:>10} {len(v):>7}  " + " / ".join(cells))
    append_record(RESULTS, {"machine": machine(), "commit": commit(), "capture": str(args.capture),
                            "photos": len(photos), "rings": figures})


if __name__ == "__main__":
    main()
