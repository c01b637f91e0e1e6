"""The train stage: decoded photos + cameras + masks -> a trained ORCa model.

Writes ``results/<capture>/train/`` atomically when training finishes (final weights, the config used,
metrics, previews, tensorboard events, ``train_report.json``, ``manifest.json``). Checkpoints live beside it
in ``train.checkpoints/`` so an interrupted run (Ctrl-C, a crash, a killed job) resumes from the last one:
``orca train`` resumes by default, ``--restart`` starts over. Checkpoints of another training config or of
other data (images, masks, cameras) are not resumed but moved to ``train.checkpoints.superseded/``.
"""

from __future__ import annotations

import argparse
import hashlib
import itertools
import json
import logging
import math
import re
import shutil
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ..artifacts import (
    atomic_dir,
    atomic_path,
    check_output_dir,
    remove_stale_temporaries,
    remove_stale_temporary_files,
    write_json,
    write_manifest,
)
from ..cameras import load_cameras
from ..config import TrainConfig, add_config_arguments, config_from_arguments
from ..errors import InputError, OrcaError
from ..provenance import FORCE_HELP, common_capture

log = logging.getLogger("orca.train")

CHECKPOINT_SUFFIX = ".checkpoints"
FINAL_WEIGHTS = "model.pt"
CHECKPOINT_FORMAT = 1


class TrainingDiverged(OrcaError):
    """The loss or a gradient became NaN/Inf; nothing was written for the bad step."""


@dataclass(frozen=True)
class TrainResult:
    out_dir: Path
    iterations: int
    seconds: float
    final_losses: dict[str, float]


# ------------------------------------------------------------------------------------------------ data


def load_image_set(decode_dir: Path, cameras_path: Path, masks_dir: Path, points_dir: Path | None = None,
                   object_margin_px: int = 4):
    """Decoded images matched by name to cameras and masks, intrinsics scaled to the decoded size, and the
    sparse depth of the surroundings when ``points_dir`` (the poses stage's COLMAP model) is given.

    Returns:
        (``orca.data.ImageSet`` in float32 on the CPU, the image names).
    """
    import torch

    from orca.data import ImageSet

    from ..mask_file import read_mask
    from ..results import load_decode

    decoded = load_decode(decode_dir)
    camera_set = load_cameras(cameras_path)
    cams = camera_set.by_name()
    names = [n for n in decoded.names if n in cams]
    missing = [n for n in decoded.names if n not in cams]
    if missing:
        log.warning("%d decoded image(s) have no camera in %s and are not used: %s",
                    len(missing), cameras_path, ", ".join(missing[:10]))
    if len(names) < 2:
        raise InputError(
            f"only {len(names)} decoded image(s) have a camera (names must match the decoded file stems)",
            cameras_path, "run the poses stage on the same capture, or pass the capture's ground_truth/cameras.json",
        )
    images, masks, valid, Ks, c2ws = [], [], [], [], []
    for name in names:
        img = decoded.linear(name)
        h, w = img.shape[:2]
        cam = cams[name]
        sx, sy = w / cam.width, h / cam.height
        if abs(sx - sy) > 1e-3 * max(sx, sy):
            raise InputError(f"camera {name} is {cam.width}x{cam.height} but the decoded image is {w}x{h} "
                             "(different aspect ratio)", cameras_path)
        mask_path = masks_dir / f"{name}.png"
        if not mask_path.is_file():
            raise InputError(f"no mask for image {name}", mask_path, "run the masks stage, or add the missing mask")
        m = read_mask(mask_path, (w, h))
        K = cam.K.copy()
        K[0] *= sx
        K[1] *= sy
        images.append(img[..., :3])
        masks.append(m)
        valid.append(~decoded.clipped(name))
        Ks.append(K)
        c2ws.append(cam.c2w)
    if not any(m.any() for m in masks):
        raise InputError("every mask is empty", masks_dir, "check the masks stage output (the object was not found)")
    t = lambda a, dt=torch.float32: torch.from_numpy(np.stack(a)).to(dt)  # noqa: E731
    depth = None
    if points_dir is not None:
        depth = _sparse_depth(points_dir, camera_set, names, np.stack(Ks), np.stack(c2ws), np.stack(masks),
                              object_margin_px)
    return ImageSet(t(images), t(masks, torch.bool), t(valid, torch.bool), t(Ks), t(c2ws), depth=depth), names


def _sparse_depth(points_dir: Path, cameras, names: list[str], K: np.ndarray, c2w: np.ndarray, masks: np.ndarray,
                  object_margin_px: int):
    """``orca.data.SparseDepth`` from the poses stage's points (see pipeline.sparse_depth)."""
    import torch

    from orca.data import SparseDepth

    from ..sparse_depth import depth_observations, load_sparse_points

    points = load_sparse_points(points_dir, cameras)
    obs = depth_observations(points, names, K, c2w, masks, object_margin_px)
    log.info("sparse depth: %d of %d points of the surroundings (%d dropped: seen on or next to the object), "
             "%d pixels, median distance %.2f", obs.points_used, len(points.xyz), obs.points_on_object,
             len(obs.distance), float(np.median(obs.distance)) if len(obs.distance) else float("nan"))
    if not len(obs.distance):
        log.warning("no sparse point of the surroundings projects into the photos off the object (%s): training "
                    "goes on without sparse depth", points_dir)
    return SparseDepth(torch.from_numpy(obs.image), torch.from_numpy(obs.uv).float(),
                       torch.from_numpy(obs.distance).float())


# ----------------------------------------------------------------------------------------------- model


def model_spec(cfg: TrainConfig):
    """The ``orca.model.ModelSpec`` a train config describes."""
    from orca.encoding import HashGridSpec
    from orca.fields import EnvironmentFieldSpec, SDFFieldSpec
    from orca.model import ModelSpec
    from orca.render import RenderSpec

    bound = cfg.scene_radius * 1.05  # the SDF grid must cover the sampled sphere
    return ModelSpec(
        sdf=SDFFieldSpec(
            encoding=cfg.sdf_encoding,
            hash_grid=HashGridSpec(levels=cfg.grid_levels, log2_table_size=cfg.grid_log2_table,
                                   max_resolution=cfg.grid_max_resolution),
            hidden=cfg.sdf_hidden, layers=cfg.sdf_layers, init_radius=cfg.sdf_init_radius, bound=bound,
            texture_grid=HashGridSpec(levels=cfg.texture_levels, log2_table_size=cfg.texture_log2_table,
                                      max_resolution=cfg.texture_max_resolution) if cfg.texture_levels else None,
        ),
        env=EnvironmentFieldSpec(
            encoding=cfg.env_encoding,
            hash_grid=HashGridSpec(levels=12, log2_table_size=cfg.env_grid_log2_table, base_resolution=16,
                                   max_resolution=1024),
            hidden=cfg.env_hidden, layers=cfg.env_layers, density_bias=cfg.env_density_bias,
            dir_freqs=cfg.env_view_freqs, contract_radius=cfg.env_contract_radius,
        ),
        render=RenderSpec(
            object_radius=cfg.scene_radius, n_coarse=cfg.n_coarse, n_fine=cfg.n_fine, upsample_steps=cfg.upsample_steps,
            band_samples=cfg.band_samples,
            env_samples=cfg.env_samples, env_fine=cfg.env_fine, env_fine_render=cfg.env_fine_render,
            depth_quantile=cfg.env_depth_quantile,
            env_near=cfg.env_near, env_far=cfg.env_far, cone_samples=cfg.cone_samples, cone_method=cfg.cone_method,
            ior=cfg.ior,
        ),
        beta_init=cfg.beta_init, beta_final=cfg.beta_final, beta_anneal=cfg.beta_anneal,
        sdf_levels_start=cfg.sdf_levels_start, sdf_levels_full=cfg.sdf_levels_full,
        background_near=cfg.background_near,
    )


def loss_weights(cfg: TrainConfig):
    from orca.model import LossWeights

    return LossWeights(**cfg.losses.model_dump())


# Config keys that do not change what the iterations compute: checkpoints made under other values resume.
# (`iterations` may change too: a finished run extended, or a time-boxed one cut short, goes on from its last
# checkpoint, with the learning-rate schedule of the new length from there.)
_RESUME_NEUTRAL_KEYS = frozenset({
    "iterations", "checkpoint_every", "preview_every", "preview_downscale", "log_every", "keep_checkpoints",
    "device", "env_fine_render", "env_depth_quantile",
})


def resolve_device(name: str):
    import torch

    if name == "auto":
        return torch.device("cuda" if torch.cuda.is_available() else "cpu")
    if name == "cuda" and not torch.cuda.is_available():
        raise OrcaError("device 'cuda' requested but PyTorch sees no CUDA GPU; use --device cpu or install a CUDA build"
                        " of torch (see the README)")
    return torch.device(name)


# ---------------------------------------------------------------------------------------- checkpoints


def checkpoint_dir_for(out_dir: Path) -> Path:
    return out_dir.with_name(out_dir.name + CHECKPOINT_SUFFIX)


# what a checkpoint folder holds: checkpoints (and atomic_path's temporary files), the live logs and previews
_CHECKPOINT_ENTRY = re.compile(r"\.?step_\d+\.pt.*|tb|previews|metrics\.jsonl")


def _checkpoints(folder: Path) -> list[Path]:
    return sorted(folder.glob("step_*.pt")) if folder.is_dir() else []


def discard_checkpoints(folder: Path) -> None:
    """Delete a checkpoint folder (``--restart``), but only one that holds nothing but what training writes."""
    foreign = [p.name for p in folder.iterdir() if not _CHECKPOINT_ENTRY.fullmatch(p.name)]
    if foreign:
        raise InputError(f"--restart would delete this checkpoint folder, but it also holds {', '.join(foreign[:5])}, "
                         "which training did not write", folder, "move those files away, then rerun")
    shutil.rmtree(folder)


def checkpoint_step(path: Path) -> int:
    """The step of ``step_XXXXXXX.pt``."""
    return int(re.fullmatch(r"step_(\d+)\.pt", path.name)[1])


def resumable_checkpoint(checkpoints: list[Path], iterations: int) -> Path | None:
    """The newest of ``checkpoints`` (sorted by step) at or below ``iterations``: a run shortened below its
    newest checkpoint goes on from an earlier one (the newer ones stay).

    Raises:
        InputError: every checkpoint is past ``iterations`` (a longer model cannot be made shorter).
    """
    if not checkpoints:
        return None
    usable = [c for c in checkpoints if checkpoint_step(c) <= iterations]
    newest = checkpoints[-1]
    if not usable:
        raise InputError(
            f"every checkpoint here is past train.iterations={iterations} (the earliest is at step "
            f"{checkpoint_step(checkpoints[0])}, the newest at {checkpoint_step(newest)}): a trained model cannot be "
            "made shorter", newest.parent,
            f"set train.iterations to at least {checkpoint_step(newest)} to finish from the newest checkpoint, or "
            "pass --restart to train from scratch (the checkpoints are then deleted)")
    if usable[-1] != newest:
        log.warning("train.iterations=%d is below the newest checkpoint's step %d (%s, kept): going on from %s, the "
                    "newest at or below it", iterations, checkpoint_step(newest), newest.name, usable[-1].name)
    return usable[-1]


def save_checkpoint(
    folder: Path, step: int, model, optimizer, scheduler, cfg: TrainConfig, keep: int, seconds: float,
    identity: dict[str, Any],
) -> Path:
    """Write ``step_XXXXXXX.pt`` atomically and drop all but the ``keep`` newest; ``seconds``: training time
    so far, over every resumed run; ``identity``: :func:`training_identity`, checked before resuming."""
    import torch

    path = folder / f"step_{step:07d}.pt"
    state = {
        "format": CHECKPOINT_FORMAT,
        "step": step,
        "model": model.state_dict(),
        "optimizer": optimizer.state_dict(),
        "scheduler": scheduler.state_dict(),
        "config": cfg.model_dump_json(),
        "identity": json.dumps(identity),
        "seconds": seconds,
    }
    with atomic_path(path) as tmp:
        torch.save(state, tmp)
    for old in _checkpoints(folder)[:-keep]:
        old.unlink(missing_ok=True)
    return path


def load_checkpoint(path: Path) -> dict[str, Any]:
    """Load a checkpoint safely (``weights_only=True``: tensors and plain containers, no code)."""
    import torch

    try:
        state = torch.load(path, map_location="cpu", weights_only=True)
    except Exception as e:  # noqa: BLE001 - any unpickling failure means a damaged file
        raise InputError(f"cannot read checkpoint: {e}", path, "delete it to resume from the one before, "
                         "or pass --restart") from e
    if not isinstance(state, dict) or state.get("format") != CHECKPOINT_FORMAT:
        raise InputError("not an ORCa checkpoint of this version", path, "pass --restart to train from scratch")
    return state


def load_weights(model, state: dict[str, Any], path: Path) -> None:
    """Load a checkpoint's weights; a file from an incompatible version of the code is a clear error."""
    try:
        model.load_state_dict(state["model"])
    except RuntimeError as e:
        raise InputError(f"the saved weights do not fit this version's network ({str(e).splitlines()[0]})", path,
                         "retrain: `orca train ... --restart`") from e


def training_identity(cfg: TrainConfig, data) -> dict[str, Any]:
    """What a checkpoint's iterations depend on: the config (but the keys of ``_RESUME_NEUTRAL_KEYS``) and a
    hash of the training data (images, masks, clipped pixels, cameras, sparse depth) as the model sees them."""
    config = {k: v for k, v in cfg.model_dump(mode="json").items() if k not in _RESUME_NEUTRAL_KEYS}
    digest = hashlib.sha256()
    depth = () if data.depth is None else (data.depth.image, data.depth.uv, data.depth.distance)
    for tensor in (data.images, data.masks, data.valid, data.K, data.c2w, *depth):
        digest.update(str(tuple(tensor.shape)).encode())
        digest.update(tensor.detach().cpu().contiguous().numpy().tobytes())
    return {"config": config, "data": digest.hexdigest()}


def identity_changes(saved: dict[str, Any] | None, current: dict[str, Any]) -> list[str]:
    """Why a checkpoint of identity ``saved`` cannot be resumed under ``current`` (empty: it can)."""
    if not saved:
        return ["it records no config or data (an older version)"]
    keys = [f"train.{k}" for k in sorted(set(saved["config"]) | set(current["config"]))
            if saved["config"].get(k) != current["config"].get(k)]
    changes = [f"{', '.join(keys)} changed"] if keys else []
    if saved.get("data") != current["data"]:
        changes.append("the images, masks or cameras changed")
    return changes


def supersede_checkpoints(ckpt_dir: Path, reasons: list[str]) -> Path:
    """Move a checkpoint folder that may not be resumed aside, into a dated folder of its own under
    ``<name>.superseded/`` (every earlier set stays there too): nothing already computed is lost, and training
    starts over."""
    root = ckpt_dir.with_name(ckpt_dir.name + ".superseded")
    root.mkdir(exist_ok=True)
    stamp = time.strftime("%Y%m%d-%H%M%S")
    aside = root / stamp
    for n in itertools.count(2):
        if not aside.exists():
            break
        aside = root / f"{stamp}-{n}"
    ckpt_dir.rename(aside)
    log.warning("not resuming from the checkpoints in %s (%s): training starts over; they are kept in %s",
                ckpt_dir, "; ".join(reasons), aside)
    return aside


# -------------------------------------------------------------------------------------------- previews


def preview_grid(model, images, K, c2w, downscale: int) -> np.ndarray:
    """One row of 8-bit pictures: photo | render | diffuse | specular | normals | opacity."""
    import torch

    from orca.imaging import render_object_image

    from ..imageio import to_srgb8

    h, w = images.shape[:2]
    hs, ws = h // downscale, w // downscale
    Ks = K.clone()
    Ks[:2] /= downscale
    with torch.no_grad():
        r = render_object_image(model, Ks, c2w, hs, ws)
    photo = images[: hs * downscale, : ws * downscale].reshape(hs, downscale, ws, downscale, 3).mean((1, 3))
    tiles = [
        to_srgb8(photo.cpu().numpy()),
        to_srgb8(r["rgb"].cpu().numpy()),
        to_srgb8(r["diffuse"].cpu().numpy()),
        to_srgb8(r["specular"].cpu().numpy()),
        np.round((r["normal"].cpu().numpy() * 0.5 + 0.5).clip(0, 1) * 255).astype(np.uint8),
        np.repeat(np.round(r["opacity"].cpu().numpy().clip(0, 1) * 255).astype(np.uint8)[..., None], 3, -1),
    ]
    return np.concatenate(tiles, axis=1)


# ------------------------------------------------------------------------------------------- the stage


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

    from orca.model import OrcaModel, objective

    started = time.time()
    ckpt_dir = checkpoint_dir_for(out_dir)
    sources = [p for p in (decode_dir, cameras_path, masks_dir, points_dir) if p is not None]
    check_output_dir(out_dir, "train", sources)  # before hours of training, not after
    capture = common_capture(sources, force=force)
    remove_stale_temporaries(out_dir)
    remove_stale_temporary_files(ckpt_dir)  # a checkpoint cut short by SIGKILL
    device = resolve_device(cfg.device)
    torch.manual_seed(cfg.seed)
    data, names = load_image_set(decode_dir, cameras_path, masks_dir, points_dir, cfg.depth_object_margin_px)
    n_img, height, width = data.shape
    log.info("train: %d images %dx%d, %d object pixels, device %s, %d iterations", n_img, width, height,
             int(data.masks.sum()), device, cfg.iterations)
    if data.depth is not None and len(data.depth) and cfg.env_far_from_points > 0:
        from ..sparse_depth import far_bound

        far = far_bound(data.depth.distance.numpy(), cfg.env_far_from_points)
        if far <= cfg.env_near:
            raise InputError(f"the sparse points are all within {far:.3g} of the photos, less than train.env_near "
                             f"({cfg.env_near})", points_dir, "check the poses stage's model, or set "
                             "train.env_far_from_points=0")
        log.info("environment samples reach %.2f (%.2f x the farthest point a photo saw; train.env_far was %g)",
                 far, cfg.env_far_from_points, cfg.env_far)
        cfg = cfg.model_copy(update={"env_far": round(far, 4)})
    if cfg.losses.sparse_depth > 0 and data.depth is None:
        log.warning("train.losses.sparse_depth is %g but no sparse points were given (--points): the term is off",
                    cfg.losses.sparse_depth)
    identity = training_identity(cfg, data)
    data = data.to(device)
    model = OrcaModel(model_spec(cfg)).to(device)
    optimizer = torch.optim.Adam(model.parameters(), lr=cfg.lr, eps=1e-15)
    decay = math.log(cfg.lr_final_ratio) / cfg.iterations
    scheduler = torch.optim.lr_scheduler.LambdaLR(optimizer, lambda it: math.exp(decay * it))
    weights = loss_weights(cfg)

    if restart and ckpt_dir.exists():
        discard_checkpoints(ckpt_dir)
    step = 0
    seconds_before = 0.0
    existing = _checkpoints(ckpt_dir)
    if existing:
        state = load_checkpoint(existing[-1])
        changes = identity_changes(json.loads(state["identity"]) if "identity" in state else None, identity)
        if changes:
            supersede_checkpoints(ckpt_dir, changes)
            existing = []
    resume = resumable_checkpoint(existing, cfg.iterations)
    ckpt_dir.mkdir(parents=True, exist_ok=True)
    if resume is not None:
        state = state if resume == existing[-1] else load_checkpoint(resume)
        load_weights(model, state, resume)
        optimizer.load_state_dict(state["optimizer"])
        scheduler.load_state_dict(state["scheduler"])
        step = int(state["step"])
        seconds_before = float(state.get("seconds", 0.0))
        log.info("resuming from %s (step %d of %d)", resume, step, cfg.iterations)
    # The sampler is reseeded from the step so a resumed run draws the batches an uninterrupted one would.
    generator = torch.Generator().manual_seed(cfg.seed * 1_000_003 + step)
    # off-object rays draw from their own stream: the object's batches do not depend on background_rays
    background_generator = torch.Generator().manual_seed(cfg.seed * 1_000_003 + step + 7_919)
    depth_generator = torch.Generator().manual_seed(cfg.seed * 1_000_003 + step + 104_729)
    use_depth = cfg.depth_rays > 0 and cfg.losses.sparse_depth > 0 and data.depth is not None and len(data.depth)

    from torch.utils.tensorboard import SummaryWriter

    from ..imageio import write_png
    from ..log import progress

    writer = SummaryWriter(str(ckpt_dir / "tb"))
    metrics_path = ckpt_dir / "metrics.jsonl"
    previews = ckpt_dir / "previews"
    stop_at = cfg.iterations if max_steps is None else min(cfg.iterations, step + max_steps)
    terms: dict[str, torch.Tensor] = {}
    t0 = time.time()
    first_step = step
    try:
        with progress() as bar, open(metrics_path, "a", encoding="utf-8") as metrics:
            task = bar.add_task("train", total=cfg.iterations, completed=step)
            while step < stop_at:
                phase = "mask" if step < cfg.mask_warmup else "joint"
                model.apply_schedule(step / cfg.iterations)
                batch = data.sample(cfg.batch_rays, cfg.object_fraction, generator)
                background = (data.sample_background(cfg.background_rays, background_generator)
                              if cfg.background_rays else None)
                depth = data.sample_depth(cfg.depth_rays, depth_generator) if use_depth else None
                total, terms, out = objective(model, batch, weights, phase, background, depth)
                if not torch.isfinite(total):
                    bad = ", ".join(k for k, v in terms.items() if not torch.isfinite(v)) or "total"
                    raise TrainingDiverged(
                        f"training diverged at step {step}: {bad} is NaN/Inf. Nothing was written for this step; "
                        f"the last good checkpoint is in {ckpt_dir}. Fix: lower train.lr (now {cfg.lr}) or "
                        "train.grad_clip, check the decoded images for NaNs, then rerun to resume."
                    )
                optimizer.zero_grad(set_to_none=True)
                total.backward()
                grad_norm = torch.nn.utils.clip_grad_norm_(model.parameters(), cfg.grad_clip)
                if not torch.isfinite(grad_norm):
                    raise TrainingDiverged(
                        f"gradients became NaN/Inf at step {step}; the last good checkpoint is in {ckpt_dir}. "
                        "Fix: lower train.lr or train.grad_clip and rerun to resume."
                    )
                optimizer.step()
                scheduler.step()
                step += 1
                if step % cfg.log_every == 0 or step == stop_at:
                    # clipped highlights are lower bounds, not targets: a PSNR over them is meaningless
                    obj = (batch.mask > 0.5) & batch.valid
                    mse = ((out.rgb - batch.rgb)[obj].square().mean()).item() if obj.any() else float("nan")
                    psnr = -10 * math.log10(max(mse, 1e-12)) if mse == mse else float("nan")
                    row = {"step": step, "seconds": round(seconds_before + time.time() - t0, 2), "phase": phase,
                           "loss": total.item(), "psnr_object": psnr,
                           "beta": model.beta.item(), "lr": scheduler.get_last_lr()[0],
                           **{k: v.item() for k, v in terms.items()}}
                    metrics.write(json.dumps(row) + "\n")
                    metrics.flush()
                    for k, v in row.items():
                        if isinstance(v, float):
                            writer.add_scalar(k, v, step)
                    bar.update(task, completed=step, description=f"train {phase} loss {total.item():.4f} "
                               f"PSNR {psnr:.1f}")
                if step % cfg.checkpoint_every == 0 or step == stop_at:
                    save_checkpoint(ckpt_dir, step, model, optimizer, scheduler, cfg, cfg.keep_checkpoints,
                                    seconds_before + time.time() - t0, identity)
                if step % cfg.preview_every == 0 or step == cfg.iterations:
                    grid = preview_grid(model, data.images[0], data.K[0], data.c2w[0], cfg.preview_downscale)
                    write_png(previews / f"step_{step:07d}.png", grid)
                    writer.add_image("preview", grid, step, dataformats="HWC")
    except KeyboardInterrupt:
        save_checkpoint(ckpt_dir, step, model, optimizer, scheduler, cfg, cfg.keep_checkpoints,
                        seconds_before + time.time() - t0, identity)
        log.warning("interrupted at step %d; checkpoint saved in %s; rerun to resume", step, ckpt_dir)
        raise
    finally:
        writer.close()
    seconds = time.time() - t0
    log.info("train: steps %d-%d in %.1f s (%.2f it/s)", first_step, step, seconds,
             (step - first_step) / max(seconds, 1e-9))
    if step < cfg.iterations:
        return None

    final_losses = {k: float(v) for k, v in terms.items()}
    with atomic_dir(out_dir, "train", sources) as tmp:
        torch.save({"format": CHECKPOINT_FORMAT, "step": step, "model": model.state_dict(),
                    "config": cfg.model_dump_json()}, tmp / FINAL_WEIGHTS)
        (tmp / "config.json").write_text(cfg.model_dump_json(indent=2) + "\n", encoding="utf-8")
        shutil.copy2(metrics_path, tmp / "metrics.jsonl")
        if previews.is_dir():
            shutil.copytree(previews, tmp / "previews")
        shutil.copytree(ckpt_dir / "tb", tmp / "tensorboard")
        write_json(tmp / "train_report.json", {
            "iterations": step, "images": names, "size": [width, height], "device": str(device),
            "seconds_this_run": round(seconds, 2), "training_seconds": round(seconds_before + seconds, 2),
            "final_losses": final_losses, "beta": model.beta.item(),
            "sparse_depth_pixels": len(data.depth) if data.depth is not None else 0,
        })
        write_manifest(tmp, stage="train", inputs={"cameras": cameras_path, "decode": decode_dir / "decode.json"},
                       config=cfg.model_dump(), started=started, capture=capture)
    log.info("train: wrote %s", out_dir)
    return TrainResult(out_dir, step, time.time() - started, final_losses)


def load_model(train_dir: Path, device: str = "cpu"):
    """The trained model of a train folder (safe loading), in eval mode."""
    from orca.model import OrcaModel

    path = Path(train_dir) / FINAL_WEIGHTS
    if not path.is_file():
        raise InputError("no trained model here", path, "run `orca train` first")
    state = load_checkpoint(path)
    cfg = TrainConfig.model_validate_json(state["config"])
    model = OrcaModel(model_spec(cfg))
    load_weights(model, state, path)
    return model.to(device).eval()


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
        cameras = args.cameras or args.ground_truth / "cameras.json"
        masks = args.masks or args.ground_truth / "masks"
    else:
        cameras, masks = args.cameras, args.masks
    if cameras is None or masks is None:
        raise InputError("train needs cameras and masks: pass --cameras and --masks, or --ground-truth")
    capture_yaml = args.capture / "capture.yaml" if args.capture is not None else None
    config = config_from_arguments(args, "train", capture_yaml)
    cfg = config.train if args.device is None else config.train.model_copy(update={"device": args.device})
    out = args.out if args.out is not None else Path(args.decode).parent / "train"
    return run_train(Path(args.decode), Path(cameras), Path(masks), out, cfg, points_dir=args.points,
                     restart=args.restart, force=args.force)
