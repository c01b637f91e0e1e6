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

FINAL_WEIGHTS = MODEL


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
