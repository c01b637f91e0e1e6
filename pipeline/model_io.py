"""The ORCa model a train config describes, the device it runs on, and the trained model's file.

``model.pt`` holds ``{"format", "step", "model" (state dict), "config" (the train config as JSON)}``: the
config rebuilds the network, so a trained model loads without anything else.
"""

from __future__ import annotations

from pathlib import Path

from .artifacts import read_json
from .cameras import CameraSet, load_cameras
from .checkpoints import CHECKPOINT_FORMAT, load_checkpoint, load_weights
from .config import TrainConfig
from .errors import InputError, OrcaError
from .layout import MANIFEST, MODEL


def model_spec(cfg: TrainConfig, photos: int = 0):
    """The ``orca.model.ModelSpec`` a train config describes, with a learned appearance for ``photos`` training
    photos (0: none)."""
    from orca.encoding import HashGridSpec
    from orca.fields import EnvironmentFieldSpec, SDFFieldSpec
    from orca.model import ModelSpec
    from orca.render import RenderSpec

    sdf, env, render = cfg.sdf, cfg.environment, cfg.render
    return ModelSpec(
        sdf=SDFFieldSpec(
            encoding=sdf.encoding, hash_grid=HashGridSpec(**sdf.hash_grid.model_dump()), hidden=sdf.hidden,
            layers=sdf.layers, init_radius=sdf.init_radius,
            texture_grid=HashGridSpec(**sdf.texture_grid.model_dump()) if sdf.texture_grid.levels else None,
            reflectance=sdf.reflectance, reflectance_init=((render.ior - 1) / (render.ior + 1)) ** 2,
            bound=render.object_radius * 1.05,  # the SDF grid must cover the sampled sphere
        ),
        env=EnvironmentFieldSpec(
            encoding=env.encoding, hash_grid=HashGridSpec(**env.hash_grid.model_dump()), hidden=env.hidden,
            layers=env.layers, dir_freqs=env.dir_freqs, contract_radius=env.contract_radius,
            density_bias=env.density_bias,
        ),
        render=RenderSpec(**render.model_dump(exclude={"env_far_from_points"})),
        beta_init=sdf.beta_init, beta_final=sdf.beta_final, beta_anneal=sdf.beta_anneal,
        sdf_levels_start=sdf.levels_start, sdf_levels_full=sdf.levels_full,
        background_near=cfg.sampler.background_near, photos=photos,
    )


def loss_weights(cfg: TrainConfig):
    from orca.model import LossWeights

    return LossWeights(**cfg.losses.model_dump())


def appearance_record(model, names: list[str]) -> dict[str, list[float]] | None:
    """Each training photo's learned gain per channel (linear RGB, relative to the photos' geometric mean),
    or None when training learned one appearance for all."""
    gains = model.photo_gains()
    if gains is None:
        return None
    return {name: [round(float(g), 5) for g in row] for name, row in zip(names, gains.detach().cpu().tolist())}


def resolve_device(name: str):
    import torch

    if name == "auto":
        return torch.device("cuda" if torch.cuda.is_available() else "cpu")
    if name == "cuda" and not torch.cuda.is_available():
        raise OrcaError("device 'cuda' requested but PyTorch sees no CUDA GPU; use --device cpu or install a CUDA build"
                        " of torch (see the README)")
    return torch.device(name)


def save_model(path: Path, model, cfg: TrainConfig, step: int) -> None:
    """The trained model's file (see the module doc)."""
    import torch

    torch.save({"format": CHECKPOINT_FORMAT, "step": step, "model": model.state_dict(),
                "config": cfg.model_dump_json()}, path)


def model_file(train_dir: Path) -> Path:
    """The trained model's file of a train folder.

    Raises:
        InputError: there is none (training has not finished there).
    """
    path = Path(train_dir) / MODEL
    if not path.is_file():
        raise InputError("no trained model here", path, "run `orca train` first (it writes model.pt when done)")
    return path


def load_model(train_dir: Path, device: str = "cpu"):
    """The trained model of a train folder (safe loading), in eval mode."""
    from orca.model import OrcaModel

    path = model_file(train_dir)
    state = load_checkpoint(path)
    cfg = TrainConfig.model_validate_json(state["config"])
    # the learned appearance has one row per training photo: the count is the saved tensor's
    gains = state["model"].get("log_gains")
    model = OrcaModel(model_spec(cfg, photos=0 if gains is None else int(gains.shape[0])))
    load_weights(model, state, path)
    return model.to(device).eval()


def training_cameras(train_dir: Path, cameras: Path | None) -> tuple[CameraSet | None, str]:
    """The cameras the model was trained with (explicit, or as the train manifest records them) and where
    they came from; ``(None, reason)`` when there are none."""
    if cameras is not None:
        return load_cameras(cameras), str(cameras)
    try:
        recorded = Path(read_json(Path(train_dir) / MANIFEST)["inputs"]["cameras"]["path"])
    except (OSError, KeyError, TypeError, ValueError):
        return None, "none (no --cameras and no train manifest recording them)"
    if not recorded.is_file():
        return None, f"none (the train manifest's {recorded} is not reachable from here)"
    return load_cameras(recorded), f"{recorded} (from the train manifest)"
