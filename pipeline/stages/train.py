"""The train stage: decoded photos + cameras + masks -> a trained ORCa model.

Writes ``results/<capture>/train/`` atomically when training finishes (final weights, the config used,
metrics, previews, tensorboard events, ``train_report.json``, ``manifest.json``). Checkpoints live beside it
in ``train.checkpoints/`` so an interrupted run (Ctrl-C, a crash, a killed job) resumes from the last one:
``orca train`` resumes by default, ``--restart`` starts over. Checkpoints of another training config or of
other data (images, masks, cameras) are not resumed but moved to ``train.checkpoints.superseded/``.
"""

from __future__ import annotations

import argparse
import logging
import shutil
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from ..artifacts import (
    atomic_dir,
    check_output_dir,
    remove_stale_temporaries,
    remove_stale_temporary_files,
    write_json,
    write_manifest,
)
from ..config import TrainConfig, add_config_arguments, config_from_arguments
from ..errors import InputError
from ..layout import (
    CAMERAS_JSON,
    CAPTURE_YAML,
    CHECKPOINTS_SUFFIX,
    DECODE_JSON,
    LIVE_TENSORBOARD,
    MASK_FILES,
    METRICS,
    MODEL,
    PREVIEWS,
    TENSORBOARD,
    TRAIN_CONFIG,
    TRAIN_REPORT,
)
from ..model_io import appearance_record, model_spec, resolve_device, save_model
from ..provenance import FORCE_HELP, common_capture
from ..training import train, with_far_from_points
from ..training_data import held_out, learns_appearance, load_image_set, posed_names, support_plane

log = logging.getLogger("orca.train")



@dataclass(frozen=True)
class TrainResult:
    out_dir: Path
    iterations: int
    seconds: float
    final_losses: dict[str, float]


def checkpoint_dir_for(out_dir: Path) -> Path:
    return out_dir.with_name(out_dir.name + CHECKPOINTS_SUFFIX)


def run_train(
    decode_dir: Path,
    cameras_path: Path,
    masks_dir: Path,
    out_dir: Path,
    cfg: TrainConfig,
    *,
    points_dir: Path | None = None,
    restart: bool = False,
    max_steps: int | None = None,
    force: bool = False,
) -> TrainResult | None:
    """Train (or resume training) and write the train folder when the last iteration is done.

    Args:
        points_dir: the poses stage's COLMAP model (``sparse/``): sparse depth of the surroundings for the
            ``losses.sparse_depth`` term.
        max_steps: stop after this many iterations in this call (checkpointing first) without finishing:
            returns None. For time-boxed runs and tests of resuming.
    """
    import torch

    from orca.model import OrcaModel

    started = time.time()
    ckpt_dir = checkpoint_dir_for(out_dir)
    sources = [p for p in (decode_dir, cameras_path, masks_dir, points_dir) if p is not None]
    check_output_dir(out_dir, "train", sources)  # before hours of training, not after
    capture = common_capture(sources, force=force)
    remove_stale_temporaries(out_dir)
    remove_stale_temporary_files(ckpt_dir)  # a checkpoint cut short by SIGKILL
    device = resolve_device(cfg.device)
    torch.manual_seed(cfg.seed)
    held = held_out(posed_names(decode_dir, cameras_path), cfg.holdout_every)
    if held:
        log.info("train: %d photo(s) held out for evaluation (train.holdout_every %d): %s", len(held),
                 cfg.holdout_every, ", ".join(held))
    data, names = load_image_set(decode_dir, cameras_path, masks_dir, points_dir, cfg.sampler.depth_object_margin_px,
                                 exclude=held)
    n_img, height, width = data.shape
    log.info("train: %d images %dx%d, %d object pixels, device %s, %d iterations", n_img, width, height,
             int(data.masks.sum()), device, cfg.iterations)
    cfg = with_far_from_points(cfg, data, points_dir)
    if cfg.losses.sparse_depth > 0 and data.depth is None:
        log.warning("train.losses.sparse_depth is %g but no sparse points were given (--points): the term is off",
                    cfg.losses.sparse_depth)
    appearance = learns_appearance(decode_dir, names, cfg.appearance)
    if appearance:
        log.info("train: learning each photo's exposure and white balance (train.appearance %s)", cfg.appearance)
    model = OrcaModel(model_spec(cfg, photos=len(names) if appearance else 0)).to(device)
    floor = support_plane(masks_dir, cameras_path)
    if floor is not None and cfg.sdf.init == "hull":
        log.info("train: the visual hull start is cut below the masks stage's support plane")
    run = train(data, model, cfg, ckpt_dir, restart=restart, max_steps=max_steps, floor=floor)
    if run.step < cfg.iterations:
        return None

    with atomic_dir(out_dir, "train", sources) as tmp:
        save_model(tmp / MODEL, model, cfg, run.step)
        (tmp / TRAIN_CONFIG).write_text(cfg.model_dump_json(indent=2) + "\n", encoding="utf-8")
        shutil.copy2(ckpt_dir / METRICS, tmp / METRICS)
        if (ckpt_dir / PREVIEWS).is_dir():
            shutil.copytree(ckpt_dir / PREVIEWS, tmp / PREVIEWS)
        shutil.copytree(ckpt_dir / LIVE_TENSORBOARD, tmp / TENSORBOARD)
        write_json(tmp / TRAIN_REPORT, {
            "iterations": run.step, "images": names, "held_out": held, "size": [width, height], "device": str(device),
            "seconds_this_run": round(run.seconds, 2), "training_seconds": round(run.seconds_total, 2),
            "final_losses": run.final_losses, "beta": model.beta.item(),
            "sparse_depth_pixels": len(data.depth) if data.depth is not None else 0,
            "appearance": appearance_record(model, names),
        })
        write_manifest(tmp, stage="train", inputs={"cameras": cameras_path, "decode": decode_dir / DECODE_JSON},
                       config=cfg.model_dump(), started=started, capture=capture)
    log.info("train: wrote %s", out_dir)
    return TrainResult(out_dir, run.step, time.time() - started, run.final_losses)


# ------------------------------------------------------------------------------------------------- CLI

EPILOG = """\
examples:
  orca train --ground-truth captures/demo/ground_truth --decode results/demo/decode \\
             --capture captures/demo --preset fast
        train from a synthetic capture's ground-truth cameras and masks, with its capture.yaml
  orca train --decode results/mug/decode --cameras results/mug/masks/cameras.json \\
             --masks results/mug/masks/masks --points results/mug/poses/sparse --out results/mug/train
        what the Snakefile runs: the masks stage's cameras and masks, and the poses stage's sparse points
        (sparse depth of the surroundings for the environment field)
  orca train ... --set iterations=500 --device cpu     a short CPU run
  orca train ... --restart                             ignore checkpoints and start over

Training resumes from the last checkpoint in <out>.checkpoints/ unless --restart is given; Ctrl-C or SIGTERM
(a scheduler cancelling the job) saves a checkpoint first. Watch it live with:
tensorboard --logdir <out>.checkpoints/tb
"""


def register(subparsers: Any) -> None:
    p = subparsers.add_parser(
        "train", help="decoded photos + cameras + masks -> trained ORCa model (SDF + environment field)",
        description="Train the ORCa model: neural SDF with diffuse head, virtual cones, 5D environment field.",
        epilog=EPILOG, formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("--decode", type=Path, required=True, help="decode stage folder")
    p.add_argument("--cameras", type=Path, default=None, help="cameras.json (poses stage or ground truth)")
    p.add_argument("--masks", type=Path, default=None, help="folder of <image name>.png object masks")
    p.add_argument("--ground-truth", type=Path, default=None,
                   help="a synthetic capture's ground_truth/ folder: its cameras.json and masks/ are used")
    p.add_argument("--capture", type=Path, default=None,
                   help="the capture folder: its capture.yaml (if any) configures training")
    p.add_argument("--points", type=Path, default=None,
                   help="the poses stage's COLMAP model (poses/sparse): sparse depth of the surroundings")
    p.add_argument("--out", type=Path, default=None, help="output folder (default: beside --decode, train/)")
    p.add_argument("--device", choices=["auto", "cpu", "cuda"], default=None, help="overrides train.device")
    p.add_argument("--restart", action="store_true", help="discard checkpoints and train from scratch")
    p.add_argument("--force", action="store_true", help=FORCE_HELP)
    add_config_arguments(p)
    p.set_defaults(func=main)


def main(args: argparse.Namespace) -> TrainResult | None:
    if args.ground_truth is not None:
        cameras = args.cameras or args.ground_truth / CAMERAS_JSON
        masks = args.masks or args.ground_truth / MASK_FILES
    else:
        cameras, masks = args.cameras, args.masks
    if cameras is None or masks is None:
        raise InputError("train needs cameras and masks: pass --cameras and --masks, or --ground-truth")
    capture_yaml = args.capture / CAPTURE_YAML if args.capture is not None else None
    config = config_from_arguments(args, "train", capture_yaml)
    cfg = config.train if args.device is None else config.train.model_copy(update={"device": args.device})
    out = args.out if args.out is not None else Path(args.decode).parent / "train"
    return run_train(Path(args.decode), Path(cameras), Path(masks), out, cfg, points_dir=args.points,
                     restart=args.restart, force=args.force)
