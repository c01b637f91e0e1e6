"""Training checkpoints: what a checkpoint folder holds, which checkpoint a run may resume from, and safe
loading.

A checkpoint folder holds ``step_XXXXXXX.pt`` files (model, optimizer and scheduler state, the config, the
training identity, the training time so far), the live metrics log, previews and tensorboard events. A
checkpoint is resumed only under the same identity (:func:`training_identity`): the same config but for the
keys that do not change what the iterations compute (``RESUME_NEUTRAL_KEYS``), and the same data. Other sets
are moved aside, never deleted (:func:`supersede_checkpoints`).
"""

from __future__ import annotations

import hashlib
import itertools
import json
import logging
import re
import shutil
import time
from pathlib import Path
from typing import Any

from pydantic import ValidationError

from .artifacts import atomic_path
from .config import TrainConfig, dotted
from .errors import InputError
from .layout import LIVE_TENSORBOARD, METRICS, PREVIEWS

log = logging.getLogger("orca.train")

CHECKPOINT_FORMAT = 1

# what a checkpoint folder holds: checkpoints (and atomic_path's temporary files), the live logs and previews
_CHECKPOINT_ENTRY = re.compile(rf"\.?step_\d+\.pt.*|{LIVE_TENSORBOARD}|{PREVIEWS}|{re.escape(METRICS)}")

# Train config keys (dotted) that do not change what the iterations compute: checkpoints made under other
# values resume. (`iterations` may change too: a finished run extended, or a time-boxed one cut short, goes on
# from its last checkpoint, with the learning-rate schedule of the new length from there.)
RESUME_NEUTRAL_KEYS = frozenset({
    "iterations", "device", "logging.checkpoint_every", "logging.preview_every", "logging.preview_downscale",
    "logging.log_every", "logging.keep_checkpoints", "render.env_fine_render", "render.depth_quantile",
})


def checkpoints(folder: Path) -> list[Path]:
    """The checkpoints of ``folder``, oldest first (none if it does not exist)."""
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
    for old in checkpoints(folder)[:-keep]:
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
    """What a checkpoint's iterations depend on: the config (all of it; :func:`identity_changes` leaves out
    ``RESUME_NEUTRAL_KEYS``) and a hash of the training data (images, masks, clipped pixels, cameras, sparse
    depth) as the model sees them."""
    config = cfg.model_dump(mode="json")
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
    try:  # an earlier version's identity holds its own keys, some since moved, the neutral ones left out
        before, now = (_compared(TrainConfig.model_validate(i["config"])) for i in (saved, current))
    except ValidationError:
        return ["its config is not one this version reads"]
    keys = [f"train.{k}" for k in sorted(set(before) | set(now)) if before.get(k) != now.get(k)]
    changes = [f"{', '.join(keys)} changed"] if keys else []
    if saved.get("data") != current["data"]:
        changes.append("the images, masks or cameras changed")
    return changes


def _compared(cfg: TrainConfig) -> dict[str, Any]:
    """The config values a checkpoint's identity compares, as dotted keys."""
    return {k: v for k, v in dotted(cfg.model_dump(mode="json")).items() if k not in RESUME_NEUTRAL_KEYS}


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
