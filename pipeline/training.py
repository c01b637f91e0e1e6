"""The optimizer loop: an ORCa model fitted to an image set, resumable from checkpoints.

:func:`train` runs Adam with an exponentially decaying learning rate, logs metrics (``metrics.jsonl`` and
tensorboard) and previews into the checkpoint folder as it goes, and checkpoints every
``train.logging.checkpoint_every`` steps, at the end of the call and on Ctrl-C. A rerun goes on from the last
checkpoint of the same training identity (see :mod:`pipeline.checkpoints`) and draws the batches an
uninterrupted run would have.
"""

from __future__ import annotations

import json
import logging
import math
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .checkpoints import (
    checkpoints,
    discard_checkpoints,
    identity_changes,
    load_checkpoint,
    load_weights,
    resumable_checkpoint,
    save_checkpoint,
    supersede_checkpoints,
    training_identity,
)
from .config import TrainConfig
from .errors import InputError, OrcaError
from .imageio import to_srgb8, write_png
from .layout import LIVE_TENSORBOARD, METRICS, PREVIEWS
from .log import progress
from .model_io import loss_weights
from .signals import raise_if_terminated
from .sparse_depth import far_bound

log = logging.getLogger("orca.train")


class TrainingDiverged(OrcaError):
    """The loss or a gradient became NaN/Inf; nothing was written for the bad step."""


@dataclass(frozen=True)
class Training:
    """Where a call of :func:`train` stopped: ``step`` (``cfg.iterations`` when finished), the seconds of this
    call's iterations and of every call's, and the loss terms of the last step."""

    step: int
    seconds: float
    seconds_total: float
    final_losses: dict[str, float]


def with_far_from_points(cfg: TrainConfig, data, points_dir: Path | None) -> TrainConfig:
    """``cfg`` with ``render.env_far`` at ``render.env_far_from_points`` times the farthest sparse point a photo
    saw (when there are sparse points and that factor is on)."""
    render = cfg.render
    if data.depth is None or not len(data.depth) or render.env_far_from_points <= 0:
        return cfg
    far = far_bound(data.depth.distance.numpy(), render.env_far_from_points)
    if far <= render.env_near:
        raise InputError(f"the sparse points are all within {far:.3g} of the photos, less than "
                         f"train.render.env_near ({render.env_near})", points_dir, "check the poses stage's model, "
                         "or set train.render.env_far_from_points=0")
    log.info("environment samples reach %.2f (%.2f x the farthest point a photo saw; train.render.env_far was %g)",
             far, render.env_far_from_points, render.env_far)
    return cfg.model_copy(update={"render": render.model_copy(update={"env_far": round(far, 4)})})


def parameter_groups(model, cfg: TrainConfig) -> list[dict]:
    """The optimizer's parameter groups: the fields and β at ``cfg.lr`` (the environment field in a group of its
    own at ``cfg.environment_lr`` when that is set), the per-photo gains (if the model learns them) at
    ``cfg.appearance_lr``. Without those two options there is one group, as checkpoints of earlier versions
    hold."""
    gains = model.log_gains
    environment = list(model.env_field.parameters()) if cfg.environment_lr else []
    taken = {id(p) for p in environment} | {id(gains)}
    groups = [{"params": [p for p in model.parameters() if id(p) not in taken]}]
    if environment:
        groups.append({"params": environment, "lr": cfg.environment_lr})
    return groups + ([{"params": [gains], "lr": cfg.appearance_lr}] if gains is not None else [])


def train(data, model, cfg: TrainConfig, ckpt_dir: Path, *, restart: bool = False,
          max_steps: int | None = None, floor: tuple[np.ndarray, float] | None = None) -> Training:
    """Fit ``model`` (on its device) to ``data`` (an ``orca.data.ImageSet`` on the CPU: its hash is part of
    the checkpoints' identity) for ``cfg.iterations`` steps, or ``max_steps`` more in this call, resuming from
    ``ckpt_dir``; ``restart`` discards the checkpoints first. ``floor``: the support plane (normal, offset) the
    hull start is cut below.

    Raises:
        TrainingDiverged: the loss or a gradient became NaN/Inf (the last good checkpoint stays).
    """
    import torch
    from torch.utils.tensorboard import SummaryWriter

    from orca.model import objective

    identity = training_identity(cfg, data)
    data = data.to(next(model.parameters()).device)
    optimizer = torch.optim.Adam(parameter_groups(model, cfg), lr=cfg.lr, betas=(0.9, cfg.adam_beta2), eps=1e-15)
    decay = math.log(cfg.lr_final_ratio) / cfg.iterations
    scheduler = torch.optim.lr_scheduler.LambdaLR(optimizer, lambda it: math.exp(decay * it))
    weights = loss_weights(cfg)

    if restart and ckpt_dir.exists():
        discard_checkpoints(ckpt_dir)
    step = 0
    seconds_before = 0.0
    existing = checkpoints(ckpt_dir)
    if existing:
        state = load_checkpoint(existing[-1])
        changes = identity_changes(json.loads(state["identity"]) if "identity" in state else None, identity)
        if changes:
            supersede_checkpoints(ckpt_dir, changes)
            existing = []
    resume = resumable_checkpoint(existing, cfg.iterations)
    ckpt_dir.mkdir(parents=True, exist_ok=True)
    if resume is None and cfg.sdf.init == "hull":
        start_from_hull(model, data, cfg, floor)
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
    use_depth = (cfg.sampler.depth_rays > 0 and cfg.losses.sparse_depth > 0 and data.depth is not None
                 and len(data.depth))

    writer = SummaryWriter(str(ckpt_dir / LIVE_TENSORBOARD))
    metrics_path = ckpt_dir / METRICS
    previews = ckpt_dir / PREVIEWS
    stop_at = cfg.iterations if max_steps is None else min(cfg.iterations, step + max_steps)
    terms: dict[str, torch.Tensor] = {}
    t0 = time.time()
    first_step = step
    try:
        with progress() as bar, open(metrics_path, "a", encoding="utf-8") as metrics:
            task = bar.add_task("train", total=cfg.iterations, completed=step)
            while step < stop_at:
                raise_if_terminated()
                phase = "mask" if step < cfg.mask_warmup else "joint"
                model.apply_schedule(step / cfg.iterations)
                batch = data.sample(cfg.batch_rays, cfg.sampler.object_fraction, generator)
                background = (data.sample_background(cfg.sampler.background_rays, background_generator)
                              if cfg.sampler.background_rays else None)
                depth = data.sample_depth(cfg.sampler.depth_rays, depth_generator) if use_depth else None
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
                if step % cfg.logging.log_every == 0 or step == stop_at:
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
                if step % cfg.logging.checkpoint_every == 0 or step == stop_at:
                    save_checkpoint(ckpt_dir, step, model, optimizer, scheduler, cfg, cfg.logging.keep_checkpoints,
                                    seconds_before + time.time() - t0, identity)
                if step % cfg.logging.preview_every == 0 or step == cfg.iterations:
                    grid = preview_grid(model, data.images[0], data.K[0], data.c2w[0], cfg.logging.preview_downscale)
                    write_png(previews / f"step_{step:07d}.png", grid)
                    writer.add_image("preview", grid, step, dataformats="HWC")
    except KeyboardInterrupt:
        save_checkpoint(ckpt_dir, step, model, optimizer, scheduler, cfg, cfg.logging.keep_checkpoints,
                        seconds_before + time.time() - t0, identity)
        log.warning("interrupted at step %d; checkpoint saved in %s; rerun to resume", step, ckpt_dir)
        raise
    finally:
        writer.close()
    seconds = time.time() - t0
    log.info("train: steps %d-%d in %.1f s (%.2f it/s)", first_step, step, seconds,
             (step - first_step) / max(seconds, 1e-9))
    return Training(step, seconds, seconds_before + seconds, {k: float(v) for k, v in terms.items()})


def start_from_hull(model, data, cfg: TrainConfig, floor: tuple[np.ndarray, float] | None = None) -> None:
    """Fit ``model``'s SDF to the visual hull of ``data``'s masks and cameras (``train.sdf.init: hull``), at the
    hash-grid levels the first step trains with; cut ``train.sdf.hull_floor_clearance`` below ``floor`` (the
    support plane: normal, offset), when given.

    Raises:
        InputError: the masks carve the whole grid away (or leave all of it): they and the cameras disagree.
    """
    import torch

    from orca.initialization import fit_sdf, signed_distance, visual_hull

    sdf, field = cfg.sdf, model.sdf_field
    started = time.time()
    model.apply_schedule(0.0)
    below = (torch.as_tensor(floor[0]), floor[1] - sdf.hull_floor_clearance) if floor is not None else None
    hull = visual_hull(data.masks, data.K, data.c2w, sdf.hull_resolution, field.spec.bound,
                       sdf.hull_carve_share, floor=below)
    try:
        target = signed_distance(hull, field.spec.bound, sdf.hull_smoothing)
    except ValueError as e:
        raise InputError(f"the training masks' visual hull has no surface ({e}): the masks and the cameras disagree",
                         fix="check the masks stage's report (views framed in red), or set "
                         "train.sdf.init=sphere") from None
    generator = torch.Generator().manual_seed(cfg.seed)
    loss = fit_sdf(field, target, field.spec.bound, sdf.hull_fit_steps, sdf.hull_fit_batch, cfg.lr, generator)
    log.info("the SDF starts from the masks' visual hull (%d of %d^3 voxels; fit to %.4f mean |error| in %.1f s)",
             int(hull.sum()), sdf.hull_resolution, loss, time.time() - started)


def preview_grid(model, images, K, c2w, downscale: int) -> np.ndarray:
    """One row of 8-bit pictures: photo | render | diffuse | specular | normals | opacity."""
    from orca.imaging import render_object_image

    h, w = images.shape[:2]
    hs, ws = h // downscale, w // downscale
    Ks = K.clone()
    Ks[:2] /= downscale
    # every ray: a preview draws random samples from the generator the steps after it draw from too
    r = render_object_image(model, Ks, c2w, hs, ws, skip_misses=False)
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
