"""A train folder holding a tiny, untrained model (seconds to build, no capture needed) and a few cameras
around it: enough for the file formats and geometry of the stages after ``train`` (render, mesh, export,
evaluate). The untrained SDF is the initial sphere of radius ``train.sdf.init_radius`` (0.7) plus a small
network correction; the environment field is a random but fixed function."""

from __future__ import annotations

from pathlib import Path

import numpy as np

TINY_MODEL = [
    "train.sdf.hash_grid.levels=4", "train.sdf.hash_grid.log2_table_size=10", "train.sdf.texture_grid.levels=2",
    "train.sdf.texture_grid.log2_table_size=10", "train.environment.hash_grid.log2_table_size=10",
    "train.sdf.hidden=16", "train.environment.hidden=16", "train.render.n_coarse=8", "train.render.n_fine=4",
    "train.render.upsample_steps=1", "train.render.band_samples=4", "train.render.env_samples=6",
    "train.render.env_fine=0", "train.render.env_fine_render=2", "train.render.depth_quantile=0.4", "train.device=cpu",
]


def write_untrained_train_dir(folder: Path, seed: int = 0, cameras: Path | None = None) -> Path:
    """``folder/model.pt`` (+ config.json and, with ``cameras``, a manifest recording them), as ``orca train``
    writes them."""
    import torch

    from orca.model import OrcaModel
    from pipeline.artifacts import write_manifest
    from pipeline.config import load_config
    from pipeline.layout import MODEL
    from pipeline.model_io import model_spec, save_model

    cfg = load_config(preset="fast", overrides=TINY_MODEL).train
    torch.manual_seed(seed)
    model = OrcaModel(model_spec(cfg))
    folder.mkdir(parents=True, exist_ok=True)
    save_model(folder / MODEL, model, cfg, step=0)
    (folder / "config.json").write_text(cfg.model_dump_json(indent=2) + "\n", encoding="utf-8")
    if cameras is not None:
        write_manifest(folder, stage="train", inputs={"cameras": cameras}, config=cfg.model_dump())
    return folder


def orbit_cameras(n: int = 4, width: int = 24, height: int = 18, distance: float = 3.0,
                  elevation_deg: float = 20.0, fov_deg: float = 50.0, prefix: str = "view"):
    """``n`` cameras on a circle around the origin (z up) looking at it, as a :class:`CameraSet`."""
    from pipeline.cameras import Camera, CameraSet, look_at

    f = 0.5 * height / np.tan(np.deg2rad(fov_deg) / 2)
    e = np.deg2rad(elevation_deg)
    cams = []
    for i in range(n):
        a = 2 * np.pi * i / n + 0.3
        eye = distance * np.array([np.cos(e) * np.cos(a), np.cos(e) * np.sin(a), np.sin(e)])
        cams.append(Camera(name=f"{prefix}{i}", width=width, height=height, fx=f, fy=f, cx=width / 2,
                           cy=height / 2, camera_to_world=look_at(eye, np.zeros(3)).tolist()))
    return CameraSet(cameras=cams)
