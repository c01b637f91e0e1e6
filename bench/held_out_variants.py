"""Training settings compared on real photos: the blowtorch's held-out photos' PSNR per variant.

    python bench/held_out_variants.py --variant base= --variant tinted=train.sdf.specular=tinted
    python bench/held_out_variants.py --photos 32 --downscale 4 --iterations 1500 --variant ...

A variant is ``name=override[;override...]`` (``train...`` settings as ``orca train --set`` takes them; nothing after
``=``: the defaults). Each variant trains the same capture: ``--photos`` blowtorch photos spread over the
walk-around with the photographers' cameras and object masks (``bench/phone_photos.py``'s capture), decoded at
1/``--downscale``, every 4th photo held out, `fast` preset; then ``orca evaluate --held-out``. Prints, per variant,
the held-out photos' PSNR on the object (by its mask) and on the whole frame, as they are and with each held-out
photo's gains matched, and the training time; appends a JSON line to bench/results/held_out_variants.jsonl.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # run as a script: bench.blowtorch

from bench.blowtorch import DATASET, append_record, commit, machine, select_photos  # noqa: E402
from bench.phone_photos import build_capture, held_out_means, run_capture  # noqa: E402

RESULTS = Path(__file__).parent / "results" / "held_out_variants.jsonl"
FIGURES = ("psnr_srgb_object", "psnr_srgb_frame", "psnr_srgb_object_matched", "psnr_srgb_frame_matched")


def parse_variant(text: str) -> tuple[str, list[str]]:
    """``name=override;override`` -> (name, overrides)."""
    name, _, overrides = text.partition("=")
    if not name:
        raise argparse.ArgumentTypeError(f"a variant needs a name before '=': {text!r}")
    return name, [o for o in overrides.split(";") if o]


def run_variants(work: Path, photos: list[Path], downscale: int, iterations: int,
                 variants: list[tuple[str, list[str]]]) -> dict[str, Any]:
    """Each variant trained and evaluated on one capture built in ``work``; its held-out figures and seconds."""
    capture = build_capture(work / "capture", photos, downscale)
    figures = {}
    for name, overrides in variants:
        results = work / f"results_{name}"
        seconds = run_capture(capture, results, [f"train.iterations={iterations}", *overrides])
        means = held_out_means(results)
        figures[name] = {"overrides": overrides, **{k: means[k] for k in FIGURES}, "seconds": seconds}
        print(f"{name:>12}: object {means['psnr_srgb_object']:.2f} dB ({means['psnr_srgb_object_matched']:.2f} "
              f"matched), frame {means['psnr_srgb_frame']:.2f} dB ({means['psnr_srgb_frame_matched']:.2f} "
              f"matched); train {seconds['train']:.0f} s", flush=True)
    return figures


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--variant", dest="variants", type=parse_variant, action="append", required=True,
                        help="name=override;override (repeat for each variant)")
    parser.add_argument("--photos", type=int, default=24, help="how many photos (evenly over the walk-around)")
    parser.add_argument("--downscale", type=int, default=8, help="decode.downscale (8: 265x177)")
    parser.add_argument("--iterations", type=int, default=1000, help="train.iterations")
    parser.add_argument("--work", type=Path, default=None, help="work folder (default: a temporary one)")
    parser.add_argument("--label", default="", help="what this run was")
    args = parser.parse_args()
    every = max(len(select_photos(DATASET)) // args.photos, 1)
    photos = select_photos(DATASET, every=every, limit=args.photos)
    work = args.work or Path(tempfile.mkdtemp(prefix="held_out_variants_"))
    figures = run_variants(work, photos, args.downscale, args.iterations, args.variants)
    append_record(RESULTS, {"machine": machine(), "commit": commit(), "label": args.label, "photos": len(photos),
                            "downscale": args.downscale, "iterations": args.iterations, "variants": figures})


if __name__ == "__main__":
    main()
