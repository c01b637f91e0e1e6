"""What several test modules share: paths, tiny configurations, a tiny untrained model and cameras around it,
synthetic images, rotations. Every test module imports it as ``helpers`` (pytest's ``pythonpath``); fixtures
are in ``conftest.py``."""

from __future__ import annotations

import base64
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np

from pipeline.alignment import Similarity
from pipeline.artifacts import write_manifest
from pipeline.cameras import Camera, CameraSet, look_at
from pipeline.config import load_config
from pipeline.layout import MODEL
from pipeline.synth.scenes import SceneSpec

ROOT = Path(__file__).resolve().parents[1]
# Real photos (RAW files, fountain-P11, calibration sets) live beside the repository, not in it.
TESTDATA = ROOT.parent / "shared" / "testdata"

# --------------------------------------------------------------------------------------------- configurations

# The visual hull's start at the size of the tests' other shrunk settings.
TINY_HULL = ["train.sdf.hull_fit_steps=20", "train.sdf.hull_fit_batch=1024", "train.sdf.hull_resolution=32"]

# A few steps of a very small model: what is tested is the bookkeeping, not the quality.

TINY_TRAIN = [
    "train.iterations=6", "train.batch_rays=64", "train.mask_warmup=2", "train.logging.checkpoint_every=2",
    "train.logging.preview_every=6", "train.logging.preview_downscale=4", "train.logging.log_every=1",
    "train.render.n_coarse=8", "train.render.n_fine=4", "train.render.env_samples=6", "train.sdf.hash_grid.levels=4",
    "train.sdf.hash_grid.log2_table_size=10", "train.environment.hash_grid.log2_table_size=10", "train.sdf.hidden=16",
    "train.environment.hidden=16", "train.device=cpu", *TINY_HULL,
]

# The whole DAG on the tiny capture: a few training steps, mesh and export as small as they go (the DAG and
# the files, not the pictures, are tested with it).
TINY_DAG = [
    "train.iterations=4", "train.batch_rays=64", "train.mask_warmup=2", "train.render.n_coarse=8",
    "train.render.n_fine=4", "train.render.upsample_steps=1", "train.render.band_samples=4",
    "train.render.env_samples=6", "train.sdf.hash_grid.levels=4", "train.sdf.hash_grid.log2_table_size=10",
    "train.sdf.texture_grid.levels=2", "train.sdf.texture_grid.log2_table_size=10",
    "train.environment.hash_grid.log2_table_size=10", "train.sdf.hidden=16", "train.environment.hidden=16",
    "mesh.resolution=32", "export.view_size=8", "export.panorama_width=16", "export.video_frames=2",
    "export.video_width=16", "export.video_height=12", "export.object_views=1", "export.object_downscale=4",
    *TINY_HULL,
]

# The network of write_untrained_train_dir: seconds to build.
TINY_MODEL = [
    "train.sdf.hash_grid.levels=4", "train.sdf.hash_grid.log2_table_size=10", "train.sdf.texture_grid.levels=2",
    "train.sdf.texture_grid.log2_table_size=10", "train.environment.hash_grid.log2_table_size=10",
    "train.sdf.hidden=16", "train.environment.hidden=16", "train.render.n_coarse=8", "train.render.n_fine=4",
    "train.render.upsample_steps=1", "train.render.band_samples=4", "train.render.env_samples=6",
    "train.render.env_fine=0", "train.render.env_fine_render=2", "train.render.depth_quantile=0.4", "train.device=cpu",
]


def snakemake_command(workdir: Path, overrides: list[str], *args: str) -> list[str]:
    """``snakemake ARGS`` on the repository's Snakefile in ``workdir`` for its capture ``captures/tiny``, with
    ``--config set=OVERRIDES`` (ARGS come first: ``--config`` takes every word after it)."""
    sets = "[" + ",".join(f'"{o}"' for o in overrides) + "]"
    return [sys.executable, "-m", "snakemake", *args, "--snakefile", str(ROOT / "Snakefile"), "--directory",
            str(workdir), "--cores", "2", "--config", 'captures=["tiny"]', f"set={sets}"]


# ------------------------------------------------------------------------------------------ scenes and models


def small(spec: SceneSpec) -> SceneSpec:
    """The same scene with coarse textures (texture generation dominates tiny renders otherwise)."""
    room = replace(spec.room, texels_per_unit=12.0, prop_texels_per_unit=32.0)
    albedo = replace(spec.object.albedo, texture_size=(128, 64))
    return replace(spec, room=room, object=replace(spec.object, albedo=albedo))


def write_untrained_train_dir(folder: Path, seed: int = 0, cameras: Path | None = None) -> Path:
    """``folder/model.pt`` (+ config.json and, with ``cameras``, a manifest recording them), as ``orca train``
    writes them, of a tiny untrained model: enough for the file formats and geometry of the stages after
    ``train``. Its SDF is the initial sphere of radius ``train.sdf.init_radius`` (0.7) plus a small network
    correction; its environment field a random but fixed function."""
    import torch

    from orca.model import OrcaModel
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
                  elevation_deg: float = 20.0, fov_deg: float = 50.0, prefix: str = "view") -> CameraSet:
    """``n`` cameras on a circle around the origin (z up) looking at it."""
    f = 0.5 * height / np.tan(np.deg2rad(fov_deg) / 2)
    e = np.deg2rad(elevation_deg)
    cams = []
    for i in range(n):
        a = 2 * np.pi * i / n + 0.3
        eye = distance * np.array([np.cos(e) * np.cos(a), np.cos(e) * np.sin(a), np.sin(e)])
        cams.append(Camera(name=f"{prefix}{i}", width=width, height=height, fx=f, fy=f, cx=width / 2,
                           cy=height / 2, camera_to_world=look_at(eye, np.zeros(3)).tolist()))
    return CameraSet(cameras=cams)


def colmap_model(cameras: CameraSet, folder: Path, *, lens: str = "PINHOLE", distortion: tuple[float, ...] = (),
                 scale: float = 1.0, text: bool = False, image_name: str = "photos/{}.JPG", points: int = 30,
                 seed: int = 0) -> Path:
    """A COLMAP model of ``cameras`` written to ``folder`` as a user would bring it: images named ``image_name``
    (a folder and another extension than the decoded photos'), cameras ``scale`` times the size (photos at full
    size, decoded smaller), ``lens`` (PINHOLE, SIMPLE_RADIAL: k; OPENCV: k1, k2, p1, p2 in ``distortion``), and
    ``points`` 3D points in a ball of radius 0.5 about the origin, each seen in every image where the lens puts
    it. Text files are written without rigs and frames (COLMAP before 3.12)."""
    from pipeline.signals import import_pycolmap

    pycolmap = import_pycolmap()
    rng = np.random.default_rng(seed)
    xyz = rng.normal(size=(points, 3))
    xyz *= 0.5 * rng.uniform(0, 1, (points, 1)) ** (1 / 3) / np.linalg.norm(xyz, axis=1, keepdims=True)
    rec = pycolmap.Reconstruction()
    for i, c in enumerate(cameras.cameras, 1):
        f = [c.fx * scale] if lens == "SIMPLE_RADIAL" else [c.fx * scale, c.fy * scale]
        cam = pycolmap.Camera(model=lens, width=round(c.width * scale), height=round(c.height * scale),
                              params=[*f, c.cx * scale, c.cy * scale, *distortion], camera_id=i)
        rec.add_camera_with_trivial_rig(cam)
        w2c = np.linalg.inv(c.c2w)
        xy = cam.img_from_cam(xyz @ w2c[:3, :3].T + w2c[:3, 3])
        image = pycolmap.Image(name=image_name.format(c.name), camera_id=i, image_id=i,
                               points2D=pycolmap.Point2DList([pycolmap.Point2D(p) for p in xy]))
        rec.add_image_with_trivial_frame(image, pycolmap.Rigid3d(pycolmap.Rotation3d(w2c[:3, :3]), w2c[:3, 3]))
    for k, x in enumerate(xyz):
        track = pycolmap.Track()
        for i in range(1, len(cameras) + 1):
            track.add_element(i, k)
        rec.add_point3D(x, track, np.full(3, 128, np.uint8))
    rec.update_point_3d_errors()
    folder.mkdir(parents=True)
    if text:
        rec.write_text(folder)
        for f in ("rigs.txt", "frames.txt"):
            (folder / f).unlink()
    else:
        rec.write(folder)
    return folder


def moved_cameras(cams: CameraSet, sim: Similarity) -> CameraSet:
    """The same cameras in the frame ``sim`` maps theirs to."""
    return CameraSet(cameras=[c.model_copy(update={"camera_to_world": sim.apply_c2w(c.c2w).tolist()})
                              for c in cams.cameras])


# ------------------------------------------------------------------------------------------ rotations, images


def rotation(axis, deg: float) -> np.ndarray:
    """``(3, 3)`` rotation about ``axis`` (any length) by ``deg`` degrees, right-handed (Rodrigues)."""
    axis = np.asarray(axis, np.float64) / np.linalg.norm(axis)
    k = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    a = np.deg2rad(deg)
    return np.eye(3) + np.sin(a) * k + (1 - np.cos(a)) * k @ k


def random_rotation(rng: np.random.Generator | int) -> np.ndarray:
    """``(3, 3)`` rotation drawn uniformly from ``rng`` (or a seed): a fixed position that is no axis-aligned
    special case."""
    rng = np.random.default_rng(rng)  # a Generator is used as it is, so its later draws follow this one
    q, r = np.linalg.qr(rng.normal(size=(3, 3)))
    q *= np.sign(np.diag(r))
    return q if np.linalg.det(q) > 0 else -q


def colourful(h: int = 96, w: int = 128) -> np.ndarray:
    """``(h, w, 3)`` linear image: smooth gradients plus soft-edged colour blobs, values in about [0.03, 0.8]."""
    yy, xx = np.mgrid[0:h, 0:w].astype(np.float64)
    yy /= h
    xx /= w
    img = np.stack([0.1 + 0.5 * xx, 0.1 + 0.45 * yy, 0.15 + 0.4 * (1 - xx) * (0.3 + yy)], axis=-1)
    for cy, cx, r, colour in [(0.3, 0.25, 0.12, (0.7, 0.15, 0.05)), (0.65, 0.7, 0.15, (0.05, 0.25, 0.6)),
                              (0.7, 0.25, 0.1, (0.2, 0.6, 0.1))]:
        d2 = ((yy - cy) * h) ** 2 + ((xx - cx) * w) ** 2
        a = 1.0 / (1.0 + np.exp((np.sqrt(d2) - r * w) / 1.5))  # soft edge, ~1.5 px
        img = img * (1 - a[..., None]) + a[..., None] * np.array(colour)
    return img.astype(np.float32)


def png_data_uri_image(src: str) -> np.ndarray:
    """The image of a ``data:image/png;base64,`` URI (as the report embeds its figures), checked to be one."""
    import cv2

    assert src.startswith("data:image/png;base64,"), src[:40]
    data = base64.b64decode(src.split(",", 1)[1], validate=True)
    assert data[:8] == b"\x89PNG\r\n\x1a\n"
    image = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_UNCHANGED)
    assert image is not None and image.size > 0
    return image
