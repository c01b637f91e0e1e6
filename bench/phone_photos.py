"""The blowtorch as a phone would give it: the same photos, each re-encoded with its own exposure and white balance
(what auto-exposure and auto white balance do, and what EXIF does not record), trained beside the originals.

    python bench/phone_photos.py                         # 24 photos at 265x177, fast preset, 600 iterations
    python bench/phone_photos.py --photos 16 --downscale 4 --iterations 1500 --no-held-out
    python bench/phone_photos.py --paired --photos 8 --downscale 16 --iterations 300   # the test's check

Both captures get the photographers' cameras (poses_bounds.npy, as known cameras) and their object masks (as
user masks), so only the photos' appearance differs. Each goes through ``orca decode``, ``poses``, ``masks``,
``train`` (every 4th photo held out) and ``evaluate --held-out``. Figures:

- gains: each re-encoded training photo's learned gains over the original's (so what the originals themselves
  vary by cancels), both relative to their geometric mean over the photos, against the gains applied; the
  largest and the median relative error over photos and channels, and the share of the variance of the applied
  exposures (stops, the gains' geometric mean) that the recovered ones explain;
- held-out PSNR on the object and the whole frame with each held-out photo's gains matched (the held-out photos
  are re-encoded too, and no model can know their exposure), re-encoded minus original.

``--paired`` trains one capture instead, holding each photo twice (as shot and re-encoded, the same camera and
mask), and measures the gains of each re-encoded photo over its original's: the gains' check for one training
(tests/stages/test_phone_photos.py), easier than the realistic run, where the two appearances are never seen side by
side. Prints the figures and appends a JSON line to bench/results/phone_photos.jsonl.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
from PIL import Image

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # run as a script: bench.blowtorch

from bench.blowtorch import DATASET, ORCA, append_record, commit, machine, select_photos  # noqa: E402
from pipeline.imageio import linear_to_srgb, srgb_to_linear  # noqa: E402
from pipeline.layout import CAPTURE_YAML, LLFF_IMAGE_NAMES, PHOTO_SUBDIR, POSES_BOUNDS, USER_MASKS  # noqa: E402

RESULTS = Path(__file__).parent / "results" / "phone_photos.jsonl"
STOPS = 0.7  # exposures within +-0.7 stop of the photos' average: what auto-exposure leaves between neighbours
TINT = 0.15  # red and blue gains within exp(+-0.15) of green: daylight vs. tungsten-ish auto white balance
JPEG_QUALITY = 92  # a phone's
HOLDOUT_EVERY = 4
TRAIN = (f"train.holdout_every={HOLDOUT_EVERY}", "train.device=cpu")
PAIRED_SUFFIX = "_phone"  # the re-encoded copy's name in a paired capture: <stem>_phone.jpg


def phone_gains(count: int, seed: int = 0, stops: float = STOPS, tint: float = TINT) -> np.ndarray:
    """``(count, 3)`` random per-channel gains: an exposure within ``stops`` and a red/blue tint within ``tint``
    (log) of green, normalized to a geometric mean of 1 per channel over the photos."""
    rng = np.random.default_rng(seed)
    log_gains = rng.uniform(-stops, stops, (count, 1)) * np.log(2) + rng.uniform(-tint, tint, (count, 3)) * [1, 0, 1]
    return np.exp(log_gains - log_gains.mean(axis=0))


def reencode(photo: Path, out: Path, gains: np.ndarray, quality: int = JPEG_QUALITY) -> None:
    """``photo`` (an sRGB JPEG) with its linear radiance times ``gains`` ``(3,)``, clipped and re-encoded as a JPEG
    at ``quality``, its EXIF kept (so decode's EXIF exposure normalization does not see the change)."""
    with Image.open(photo) as im:
        exif = im.info.get("exif", b"")
        srgb = np.asarray(im.convert("RGB"), np.float32) / 255.0
    linear = np.clip(srgb_to_linear(srgb) * np.asarray(gains, np.float32), 0.0, 1.0)
    encoded = np.round(linear_to_srgb(linear) * 255.0).astype(np.uint8)
    Image.fromarray(encoded).save(out, quality=quality, exif=exif)


def build_capture(folder: Path, photos: Sequence[Path], downscale: int, gains: np.ndarray | None = None,
                  dataset: Path = DATASET) -> Path:
    """A capture of ``photos`` (linked, or re-encoded with ``gains`` ``(len(photos), 3)``) with the dataset's
    poses (known cameras) and object masks (user masks) linked in, decoded at 1/``downscale``."""
    (folder / PHOTO_SUBDIR).mkdir(parents=True)
    (folder / USER_MASKS).mkdir()
    for i, p in enumerate(photos):
        if gains is None:
            (folder / PHOTO_SUBDIR / p.name).symlink_to(p.resolve())
        else:
            reencode(p, folder / PHOTO_SUBDIR / p.name, gains[i])
        (folder / USER_MASKS / f"{p.stem}.png").symlink_to((dataset / USER_MASKS / f"{p.stem}.png").resolve())
    for name in (POSES_BOUNDS, LLFF_IMAGE_NAMES):
        (folder / name).symlink_to((dataset / name).resolve())
    (folder / CAPTURE_YAML).write_text(f"decode:\n  downscale: {downscale}\n", encoding="utf-8")
    return folder


def run_capture(capture: Path, results: Path, overrides: Sequence[str] = (), held_out: bool = True
                ) -> dict[str, float]:
    """decode -> poses -> masks -> train (-> evaluate --held-out unless ``held_out`` is off) into
    ``results/<stage>``; seconds per stage.

    Raises:
        RuntimeError: a stage failed (its log's tail in the message).
    """
    r = {s: results / s for s in ("decode", "poses", "masks", "train", "evaluate")}
    sets = [a for o in [*TRAIN, *overrides] for a in ("--set", o)]
    commands = {
        "decode": ["decode", capture, "--out", r["decode"]],
        "poses": ["poses", capture, "--decode", r["decode"], "--out", r["poses"]],
        "masks": ["masks", capture, "--decode", r["decode"], "--poses", r["poses"], "--out", r["masks"]],
        "train": ["train", "--decode", r["decode"], "--cameras", r["masks"] / "cameras.json", "--masks",
                  r["masks"] / "masks", "--capture", capture, "--preset", "fast", "--out", r["train"], *sets],
        "evaluate": ["evaluate", r["train"], "--held-out", "--out", r["evaluate"], "--device", "cpu"],
    }
    if not held_out:
        del commands["evaluate"]
    seconds = {}
    results.mkdir(parents=True, exist_ok=True)
    for stage, args in commands.items():
        started = time.perf_counter()
        proc = subprocess.run([str(ORCA), *map(str, args)], capture_output=True, text=True)
        seconds[stage] = round(time.perf_counter() - started, 1)
        (results / f"{stage}.log").write_text(proc.stdout + proc.stderr, encoding="utf-8")
        if proc.returncode:
            raise RuntimeError(f"orca {stage} failed on {capture}:\n{(proc.stdout + proc.stderr)[-3000:]}")
    return seconds


def learned_gains(results: Path) -> dict[str, np.ndarray]:
    """Each training photo's learned gains ``(3,)`` (train_report.json's appearance)."""
    report = json.loads((results / "train" / "train_report.json").read_text(encoding="utf-8"))
    if not report.get("appearance"):
        raise RuntimeError(f"{results / 'train'} learned no appearance (train.appearance off?)")
    return {name: np.asarray(g) for name, g in report["appearance"].items()}


def held_out_means(results: Path) -> dict[str, float]:
    return json.loads((results / "evaluate" / "evaluate.json").read_text(encoding="utf-8"))["held_out"]["mean"]


def gain_recovery(recovered: dict[str, np.ndarray], applied: dict[str, np.ndarray]) -> dict[str, Any]:
    """How well ``recovered`` gains ``(3,)`` per photo name match the ``applied`` ones, both relative to their
    geometric mean over the photos: the gain figures of the module doc."""
    names = sorted(recovered)
    found = np.stack([recovered[n] for n in names])
    found /= np.exp(np.log(found).mean(axis=0))
    truth = np.stack([applied[n] for n in names])
    truth /= np.exp(np.log(truth).mean(axis=0))
    error = np.abs(found / truth - 1)
    applied_stops, recovered_stops = np.log2(truth).mean(axis=1), np.log2(found).mean(axis=1)
    return {
        "gain_error_median": float(np.median(error)), "gain_error_max": float(error.max()),
        "applied_stops_range": float(np.ptp(applied_stops)),
        "exposure_explained": float(1 - np.var(applied_stops - recovered_stops) / np.var(applied_stops)),
        "per_photo": {n: {"applied": truth[i].round(4).tolist(), "recovered": found[i].round(4).tolist()}
                      for i, n in enumerate(names)},
    }


def compare(original: Path, phone: Path, applied: dict[str, np.ndarray], held_out: bool = True) -> dict[str, Any]:
    """The figures of the module doc from the two runs' result folders and the gains applied per photo name (the
    gains' alone without ``held_out``)."""
    base, learned = learned_gains(original), learned_gains(phone)
    figures = gain_recovery({n: learned[n] / base[n] for n in learned}, applied)
    if held_out:
        before, after = held_out_means(original), held_out_means(phone)
        keys = ("psnr_srgb_object_matched", "psnr_srgb_frame_matched", "psnr_srgb_object", "psnr_srgb_frame")
        figures |= {"held_out_original": {k: before[k] for k in keys}, "held_out_phone": {k: after[k] for k in keys},
                    "held_out_drop_db": {k: before[k] - after[k] for k in keys}}
    return figures


def build_paired_capture(folder: Path, photos: Sequence[Path], downscale: int, gains: np.ndarray,
                         dataset: Path = DATASET) -> Path:
    """:func:`build_capture` of ``photos`` as shot, plus each re-encoded with its ``gains`` (``(len(photos), 3)``;
    named ``<stem>{PAIRED_SUFFIX}.jpg``) with the same camera (the LLFF rows written for both names instead of the
    dataset's linked in) and object mask. One training then sees every view in both appearances, and the learned
    gains' ratio within each pair is the recovered re-encoding: the gains' check at the cost of one training."""
    build_capture(folder, photos, downscale, dataset=dataset)
    listed = (dataset / LLFF_IMAGE_NAMES).read_text(encoding="utf-8").split()
    rows = dict(zip(sorted(listed), np.load(dataset / POSES_BOUNDS)))
    poses = {p.name: rows[p.name] for p in photos}
    for p, g in zip(photos, gains):
        copy = folder / PHOTO_SUBDIR / f"{p.stem}{PAIRED_SUFFIX}.jpg"
        reencode(p, copy, g)
        (folder / USER_MASKS / f"{copy.stem}.png").symlink_to((dataset / USER_MASKS / f"{p.stem}.png").resolve())
        poses[copy.name] = rows[p.name]
    names = sorted(poses)
    for name in (POSES_BOUNDS, LLFF_IMAGE_NAMES):
        (folder / name).unlink()  # build_capture's links to the dataset's rows
    (folder / LLFF_IMAGE_NAMES).write_text("\n".join(names) + "\n", encoding="utf-8")
    np.save(folder / POSES_BOUNDS, np.stack([poses[n] for n in names]))
    return folder


def paired_recovery(results: Path, applied: dict[str, np.ndarray]) -> dict[str, Any]:
    """:func:`gain_recovery` of a :func:`build_paired_capture` run: each re-encoded photo's learned gains over its
    original's."""
    learned = learned_gains(results)
    recovered = {n: learned[f"{n}{PAIRED_SUFFIX}"] / learned[n] for n in learned if not n.endswith(PAIRED_SUFFIX)}
    return gain_recovery(recovered, applied)


def run(work: Path, photos: Sequence[Path], downscale: int, overrides: Sequence[str] = (), seed: int = 0,
        held_out: bool = True) -> dict[str, Any]:
    """Both captures built in ``work`` and run; :func:`compare`'s figures and the seconds per stage."""
    gains = phone_gains(len(photos), seed)
    original = build_capture(work / "original", photos, downscale)
    phone = build_capture(work / "phone", photos, downscale, gains)
    seconds = {"original": run_capture(original, work / "results_original", overrides, held_out),
               "phone": run_capture(phone, work / "results_phone", overrides, held_out)}
    applied = {p.stem: gains[i] for i, p in enumerate(photos)}
    return {**compare(work / "results_original", work / "results_phone", applied, held_out), "seconds": seconds}


def run_paired(work: Path, photos: Sequence[Path], downscale: int, overrides: Sequence[str] = (), seed: int = 0
               ) -> dict[str, Any]:
    """:func:`build_paired_capture` in ``work``, trained on every photo; :func:`paired_recovery`'s figures and the
    seconds per stage."""
    gains = phone_gains(len(photos), seed)
    capture = build_paired_capture(work / "paired", photos, downscale, gains)
    seconds = run_capture(capture, work / "results_paired", [*overrides, "train.holdout_every=0"], held_out=False)
    applied = {p.stem: g for p, g in zip(photos, gains)}
    return {**paired_recovery(work / "results_paired", applied), "seconds": seconds}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--photos", type=int, default=24, help="how many photos (evenly over the walk-around)")
    parser.add_argument("--downscale", type=int, default=8, help="decode.downscale (8: 265x177)")
    parser.add_argument("--seed", type=int, default=0, help="of the applied gains")
    parser.add_argument("--set", dest="overrides", action="append", default=[], help="train config overrides")
    parser.add_argument("--work", type=Path, default=None, help="work folder (default: a temporary one)")
    parser.add_argument("--no-held-out", dest="held_out", action="store_false",
                        help="the gains alone: no orca evaluate --held-out (the held-out figures are left out)")
    parser.add_argument("--iterations", type=int, default=600, help="train.iterations")
    parser.add_argument("--paired", action="store_true",
                        help="one capture with each photo as shot and re-encoded, one training (the test's check)")
    args = parser.parse_args()
    every = max(len(select_photos(DATASET)) // args.photos, 1)
    photos = select_photos(DATASET, every=every, limit=args.photos)
    overrides = [f"train.iterations={args.iterations}", *args.overrides]
    work = args.work or Path(tempfile.mkdtemp(prefix="phone_photos_"))
    if args.paired:
        figures = run_paired(work, photos, args.downscale, overrides, args.seed)
    else:
        figures = run(work, photos, args.downscale, overrides, args.seed, args.held_out)
    print(json.dumps({k: v for k, v in figures.items() if k != "per_photo"}, indent=1))
    append_record(RESULTS, {"machine": machine(), "commit": commit(), "photos": len(photos), "paired": args.paired,
                            "downscale": args.downscale, "seed": args.seed, "overrides": overrides, **figures})


if __name__ == "__main__":
    main()
