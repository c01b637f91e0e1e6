"""The train stage. On the tiny synthetic capture: interrupted + resumed training continues where it stopped,
safe checkpoints, a clear stop on NaNs, and the final artifact only once training is complete. On a tiny
non-spherical capture: a minute or two of CPU training learns the object's shape (the SDF starts as a sphere,
whose normals are already right for a sphere; the blob's bumps, concave and convex regions are what make that
test able to fail)."""

from __future__ import annotations

import json
from dataclasses import replace

import cv2
import numpy as np
import pytest
import torch
from helpers import TINY_TRAIN, small

from pipeline.checkpoints import load_checkpoint
from pipeline.config import DecodeConfig, load_config
from pipeline.errors import InputError
from pipeline.imageio import read_exr, read_image
from pipeline.metrics import iou
from pipeline.model_io import load_model, model_spec
from pipeline.stages.decode import run_decode
from pipeline.stages.train import checkpoint_dir_for, run_train
from pipeline.training import TrainingDiverged
from pipeline.training_data import load_image_set

# ------------------------------------------------------------------------------ resume, checkpoints, messages


def _cfg(*extra):
    return load_config(preset="fast", overrides=[*TINY_TRAIN, *extra]).train


def test_interrupted_training_resumes_from_its_checkpoint(tiny_capture, tiny_decode, tmp_path):
    gt = tiny_capture / "ground_truth"
    out = tmp_path / "train"
    cfg = _cfg()
    assert run_train(tiny_decode, gt / "cameras.json", gt / "masks", out, cfg, max_steps=4) is None
    assert not out.exists(), "no final artifact before training is complete"
    ckpts = sorted(checkpoint_dir_for(out).glob("step_*.pt"))
    assert ckpts[-1].name == "step_0000004.pt"
    result = run_train(tiny_decode, gt / "cameras.json", gt / "masks", out, cfg)
    assert result is not None and result.iterations == 6
    steps = [json.loads(line)["step"] for line in (out / "metrics.jsonl").read_text().splitlines()]
    assert steps == [1, 2, 3, 4, 5, 6], "the resumed run continued at step 5, it did not restart from zero"
    assert (out / "model.pt").is_file() and (out / "manifest.json").is_file()
    assert list((out / "previews").glob("*.png")) and (out / "train_report.json").is_file()
    state = load_checkpoint(out / "model.pt")
    assert state["step"] == 6
    model = load_model(out)
    assert model.beta.item() > 0


def test_a_terminated_orca_train_checkpoints_and_resumes(tiny_capture, tiny_decode, tmp_path):
    """SIGTERM (what a scheduler sends) mid-training: a checkpoint at the step reached, exit code 143, and the
    next run continues from there."""
    import signal
    import subprocess
    import sys
    import time

    gt = tiny_capture / "ground_truth"
    out = tmp_path / "train"
    overrides = [a for o in TINY_TRAIN if o.split("=")[0] not in ("train.iterations", "train.logging.checkpoint_every")
                 for a in ("--set", o)]
    cmd = [sys.executable, "-m", "pipeline.cli", "train", "--decode", str(tiny_decode), "--ground-truth", str(gt),
           "--out", str(out), "--preset", "fast", *overrides, "--set", "train.iterations=100000",
           "--set", "train.logging.checkpoint_every=100000"]
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    metrics = checkpoint_dir_for(out) / "metrics.jsonl"
    deadline = time.time() + 120
    while time.time() < deadline and not (metrics.is_file() and len(metrics.read_text().splitlines()) >= 3):
        time.sleep(0.2)
    proc.send_signal(signal.SIGTERM)
    output, _ = proc.communicate(timeout=60)
    assert proc.returncode == 143, output[-2000:]
    ckpts = sorted(checkpoint_dir_for(out).glob("step_*.pt"))
    assert ckpts, "no checkpoint was written on SIGTERM"
    step = load_checkpoint(ckpts[-1])["step"]
    assert step >= 3 and not out.exists()
    assert not list(tmp_path.rglob("*partial*")), "a temporary file was left behind"
    resumed = run_train(tiny_decode, gt / "cameras.json", gt / "masks", out, _cfg(f"train.iterations={step + 2}"))
    assert resumed is not None and resumed.iterations == step + 2


def _steps(folder):
    return [json.loads(line)["step"] for line in (folder / "metrics.jsonl").read_text().splitlines()]


def test_checkpoints_of_another_config_or_other_data_are_set_aside_not_resumed(tiny_capture, tiny_decode, tmp_path):
    import shutil

    gt = tiny_capture / "ground_truth"
    out = tmp_path / "train"
    ckpts, aside = checkpoint_dir_for(out), tmp_path / "train.checkpoints.superseded"
    run_train(tiny_decode, gt / "cameras.json", gt / "masks", out, _cfg(), max_steps=2)
    # what only changes the bookkeeping (or the render-time settings) resumes
    run_train(tiny_decode, gt / "cameras.json", gt / "masks", out, _cfg("train.logging.log_every=2",
              "train.render.depth_quantile=0.4"), max_steps=2)
    assert _steps(ckpts) == [1, 2, 4] and not aside.exists()
    # another network, or another loss weight: the old run is kept aside (every earlier set too), the new one
    # starts from zero
    for change, last_aside in (("train.sdf.hidden=32", ["step_0000004.pt"]),
                               ("train.losses.eikonal=0.2", ["step_0000004.pt", "step_0000002.pt"])):
        run_train(tiny_decode, gt / "cameras.json", gt / "masks", out, _cfg(change), max_steps=2)
        assert _steps(ckpts) == [1, 2], change
        kept = sorted(aside.iterdir())
        assert [sorted(p.name for p in k.glob("step_*.pt"))[-1] for k in kept] == last_aside, change
    # the same config on other masks (one view's mask edited) starts over too
    masks = tmp_path / "masks"
    shutil.copytree(gt / "masks", masks)
    first = sorted(masks.glob("*.png"))[0]
    from pipeline.imageio import read_image, write_png

    m = read_image(first)
    m[m.shape[0] // 2] = m.max()  # a line across the view marked object
    write_png(first, m)
    run_train(tiny_decode, gt / "cameras.json", masks, out, _cfg("train.losses.eikonal=0.2"), max_steps=3)
    assert _steps(ckpts) == [1, 2, 3]
    # --restart discards the checkpoints outright
    assert run_train(tiny_decode, gt / "cameras.json", masks, out, _cfg("train.losses.eikonal=0.2"),
                     restart=True, max_steps=1) is None
    assert _steps(ckpts) == [1]


def test_nan_in_training_stops_with_a_clear_message(tiny_capture, tiny_decode, tmp_path, monkeypatch):
    from orca import data as data_module

    original = data_module.ImageSet.sample

    def poisoned(self, *args, **kwargs):
        batch = original(self, *args, **kwargs)
        return batch._replace(rgb=torch.full_like(batch.rgb, float("nan")))  # e.g. a NaN in a decoded image

    monkeypatch.setattr(data_module.ImageSet, "sample", poisoned)
    gt = tiny_capture / "ground_truth"
    out = tmp_path / "train"
    with pytest.raises(TrainingDiverged, match="NaN"):
        run_train(tiny_decode, gt / "cameras.json", gt / "masks", out, _cfg("train.mask_warmup=0"))
    assert not out.exists()
    assert not list(checkpoint_dir_for(out).glob("step_*.pt")), "no checkpoint of a diverged step"


def test_missing_masks_are_named(tiny_capture, tiny_decode, tmp_path):
    gt = tiny_capture / "ground_truth"
    (tmp_path / "masks").mkdir()
    with pytest.raises(InputError, match="no mask"):
        run_train(tiny_decode, gt / "cameras.json", tmp_path / "masks", tmp_path / "train", _cfg())


def test_training_lowers_the_loss_on_the_tiny_capture(tiny_capture, tiny_decode, tmp_path):
    gt = tiny_capture / "ground_truth"
    steps = ("train.iterations=40", "train.mask_warmup=20", "train.logging.checkpoint_every=40",
             "train.logging.preview_every=40")
    mask = {}
    for start in ("sphere", "hull"):
        out = tmp_path / start
        run_train(tiny_decode, gt / "cameras.json", gt / "masks", out, _cfg(*steps, f"train.sdf.init={start}"))
        rows = [json.loads(line) for line in (out / "metrics.jsonl").read_text().splitlines()]
        mask[start] = np.array([r["mask"] for r in rows])
    assert mask["sphere"][15:20].mean() < 0.7 * mask["sphere"][:5].mean(), "the silhouette warm-up lowers the mask loss"
    assert mask["hull"][:5].mean() < 0.3 * mask["sphere"][:5].mean(), "the visual hull starts with the silhouettes"


def test_a_learned_appearance_is_reported_per_photo_and_loads_with_the_model(tiny_capture, tiny_decode, tmp_path):
    """train.appearance: a gain per channel and training photo, written to train_report.json (geometric mean 1)
    and into model.pt, from which the model loads; auto learns one for JPEG photos, not for RAW ones."""
    from pipeline.results import load_decode
    from pipeline.training_data import learns_appearance

    gt = tiny_capture / "ground_truth"
    out = tmp_path / "train"
    run_train(tiny_decode, gt / "cameras.json", gt / "masks", out, _cfg("train.appearance=true"))
    report = json.loads((out / "train_report.json").read_text())
    gains = np.array([report["appearance"][n] for n in report["images"]])
    assert gains.shape == (4, 3) and np.allclose(np.log(gains).mean(axis=0), 0, atol=1e-4)
    assert not np.allclose(gains, 1), "six steps of training moved them"
    model = load_model(out)
    assert torch.allclose(model.photo_gains(), torch.tensor(gains, dtype=torch.float32), atol=1e-4)
    from pipeline.report.reader import Reader
    from pipeline.report.sections import section_train

    _, section = section_train(Reader(tmp_path, tmp_path / "page"), out)
    assert section["appearance"].uri.startswith("data:image/png")  # the report plots them

    names = report["images"]
    assert not learns_appearance(tiny_decode, names, "auto") and learns_appearance(tiny_decode, names, True)
    photos = tmp_path / "jpegs"
    (photos / "images").mkdir(parents=True)
    for name in names:  # the same photos as 8-bit JPEGs
        cv2.imwrite(str(photos / "images" / f"{name}.jpg"), load_decode(tiny_decode).srgb(name)[..., ::-1])
    run_decode(photos, tmp_path / "decode_jpeg", DecodeConfig())
    assert learns_appearance(tmp_path / "decode_jpeg", names, "auto")
    assert not learns_appearance(tmp_path / "decode_jpeg", names, False)


@pytest.mark.slow
def test_the_poses_stages_points_give_sparse_depth(sfm_sphere_capture, sfm_sphere_decode, sfm_sphere_poses, tmp_path):
    """`--points`: the SfM points of the room, off the object, become rays whose depth the field is taught."""
    from pipeline.training_data import load_image_set

    _, poses, _ = sfm_sphere_poses
    masks = sfm_sphere_capture / "ground_truth" / "masks"
    data, names = load_image_set(sfm_sphere_decode, poses / "cameras.json", masks, poses / "sparse")
    depth = data.depth
    assert depth is not None and len(depth) > 1000 and set(depth.image.tolist()) == set(range(len(names)))
    # every ray goes through a pixel off the object (the points seen on it were dropped)
    col, row = depth.uv[:, 0].long(), depth.uv[:, 1].long()
    assert not data.masks[depth.image, row, col].any()
    # the room is around the object, beyond it: no point inside the object's sphere (radius ~0.64 here)
    from orca.rays import camera_rays

    origins, dirs, _ = camera_rays(depth.uv, data.K[depth.image], data.c2w[depth.image])
    ends = origins + depth.distance[:, None] * dirs
    assert ends.norm(dim=-1).min() > 0.6

    # with the ground-truth cameras (no to_colmap) the points are placed by the camera centres: each lands on
    # the same pixels of the photos that saw it as through the poses stage's cameras
    from pipeline.cameras import load_cameras
    from pipeline.sparse_depth import load_sparse_points

    sfm = load_cameras(poses / "cameras.json")
    truth = load_cameras(sfm_sphere_capture / "ground_truth" / "cameras.json")
    a, b = load_sparse_points(poses / "sparse", sfm), load_sparse_points(poses / "sparse", truth)
    assert a.observers == b.observers

    def pixels(points, cameras):
        by_name = cameras.by_name()
        out = []
        for x, seen in zip(points.xyz, points.observers):
            cam = by_name[seen[0]]
            p = np.linalg.inv(cam.c2w)[:3] @ np.append(x, 1.0)
            out.append(cam.K[:2, :2] @ (p[:2] / p[2]) + cam.K[:2, 2])
        return np.array(out)

    # measured 0.56 px: SfM's cameras are ~0.1 degrees off the truth; a misplaced model is tens of pixels off
    assert np.median(np.linalg.norm(pixels(a, sfm) - pixels(b, truth), axis=1)) < 1.0

    out = tmp_path / "train"
    result = run_train(sfm_sphere_decode, poses / "cameras.json", masks, out,
                       _cfg("train.sampler.depth_rays=32"), points_dir=poses / "sparse")
    assert result is not None and 0 < result.final_losses["sparse_depth"] <= 1
    assert json.loads((out / "train_report.json").read_text())["sparse_depth_pixels"] == len(depth)
    # the environment's samples reach just past the farthest point, and the saved model renders with that bound
    far = json.loads((out / "config.json").read_text())["render"]["env_far"]
    assert far == pytest.approx(1.25 * np.quantile(depth.distance.numpy(), 0.999), rel=1e-3)
    assert far < 0.5 * load_config(preset="fast").train.render.env_far
    assert load_model(out).spec.render.env_far == far


# ------------------------------------------------------------------------------------------- learning a shape


QUICK = [
    "train.iterations=300", "train.batch_rays=128", "train.mask_warmup=200", "train.logging.checkpoint_every=300",
    "train.logging.preview_every=300", "train.logging.log_every=10", "train.lr=0.01", "train.device=cpu",
    "train.sampler.background_rays=128",
]


@pytest.fixture(scope="module")
def blob(tmp_path_factory):
    pytest.importorskip("mitsuba")
    from pipeline.synth import SCENES, SynthOptions, render_capture

    root = tmp_path_factory.mktemp("blob")
    options = SynthOptions(views=8, width=64, height=48, spp=16, env_size=16, coverage_spp=9, seed=3)
    spec = small(SCENES["blob"])
    spec = replace(spec, rig=replace(spec.rig, fov_x_deg=25.0))  # the blob fills the small frame
    capture = render_capture(spec, root / "blob", options)
    return capture, run_decode(capture, root / "decode", DecodeConfig()).out_dir


def shape_errors(model, capture, decode) -> tuple[float, float]:
    """Mean angle (degrees) between rendered and true normals over the true masks, and the mean mask IoU
    (opacity >= 0.5), over every view."""
    from orca.imaging import render_object_image

    gt = capture / "ground_truth"
    data, names = load_image_set(decode, gt / "cameras.json", gt / "masks")
    errors, ious = [], []
    for i, name in enumerate(names):
        n, h, w = data.shape
        with torch.no_grad():
            r = render_object_image(model, data.K[i], data.c2w[i], h, w)
        pred, opaque = r["normal"].numpy(), r["opacity"].numpy() >= 0.5
        true = read_exr(gt / "normals" / f"{name}.exr")[..., :3]
        silhouette = read_image(gt / "masks" / f"{name}.png") > 127
        mask = silhouette & (np.linalg.norm(true, axis=-1) > 0.5)
        p = pred[mask] / np.linalg.norm(pred[mask], axis=-1, keepdims=True).clip(1e-8)
        t = true[mask] / np.linalg.norm(true[mask], axis=-1, keepdims=True)
        errors.append(np.degrees(np.arccos((p * t).sum(-1).clip(-1, 1))))
        ious.append(iou(opaque, silhouette))
    return float(np.concatenate(errors).mean()), float(np.mean(ious))


def held_out_losses(model, capture, decode, cfg) -> dict[str, float]:
    """The objective's terms on one fixed batch of 4096 rays (per-step batches are too noisy to compare)."""
    from orca.model import objective
    from pipeline.model_io import loss_weights

    gt = capture / "ground_truth"
    data, _ = load_image_set(decode, gt / "cameras.json", gt / "masks")
    batch = data.sample(4096, cfg.sampler.object_fraction, torch.Generator().manual_seed(123))
    _, terms, _ = objective(model, batch, loss_weights(cfg), "joint")
    return {k: float(v) for k, v in terms.items()}


@pytest.mark.slow(seconds=150)
def test_a_minute_of_training_learns_the_blobs_shape_and_lowers_the_loss(blob, tmp_path):
    from orca.model import OrcaModel

    capture, decode = blob
    gt = capture / "ground_truth"
    cfg = load_config(preset="fast", overrides=QUICK).train
    torch.manual_seed(cfg.seed)
    initial_model = OrcaModel(model_spec(cfg)).eval()
    initial_normals, initial_iou = shape_errors(initial_model, capture, decode)
    initial_losses = held_out_losses(initial_model, capture, decode, cfg)

    out = tmp_path / "train"
    run_train(decode, gt / "cameras.json", gt / "masks", out, cfg)
    model = load_model(out)
    normals, iou = shape_errors(model, capture, decode)
    losses = held_out_losses(model, capture, decode, cfg)
    print(f"normal error {initial_normals:.1f} -> {normals:.1f} deg, mask IoU {initial_iou:.3f} -> {iou:.3f}, "
          f"losses {initial_losses} -> {losses}")
    assert losses["mask"] < 0.5 * initial_losses["mask"]
    assert losses["photometric"] < 0.7 * initial_losses["photometric"]
    assert iou > 0.9 and iou > initial_iou + 0.1
    # measured: 25.4 -> 13.7 deg, IoU 0.78 -> 0.95, mask loss x0.37, photometric x0.32; random normals: ~90 deg
    assert normals < 20.0 and normals < 0.7 * initial_normals


def zero_set_iou(model, data) -> float:
    """Mean IoU over the views of the pixels whose ray crosses the SDF's zero level (128 samples through the
    object's sphere) and the masks: the shape's silhouettes, whatever the density's sharpness β."""
    from orca.rays import camera_rays

    n, h, w = data.shape
    cols, rows = torch.meshgrid(torch.arange(w) + 0.5, torch.arange(h) + 0.5, indexing="xy")
    uv = torch.stack([cols, rows], -1).reshape(-1, 2)
    radius = model.spec.render.object_radius
    ious = []
    for i in range(n):
        origins, dirs, _ = camera_rays(uv, data.K[i], data.c2w[i])
        centre = -(origins * dirs).sum(-1)  # the distance along each ray nearest the object's centre
        t = centre[:, None] + torch.linspace(-radius, radius, 128)[None]
        with torch.no_grad():
            sdf = model.sdf_field.sdf((origins[:, None] + t[..., None] * dirs[:, None]).reshape(-1, 3))
        hit = (sdf.reshape(len(uv), -1).min(-1).values < 0).reshape(h, w).numpy()
        ious.append(iou(hit, data.masks[i].numpy()))
    return float(np.mean(ious))


@pytest.mark.slow(seconds=85)
def test_the_visual_hull_start_has_the_blobs_silhouettes_before_any_step(blob):
    """train.sdf.init=hull: before any step the SDF fitted to the masks' visual hull has the silhouettes and far
    better normals than the sphere start."""
    from orca.model import OrcaModel
    from pipeline.training import start_from_hull

    capture, decode = blob
    gt = capture / "ground_truth"
    cfg = load_config(preset="fast", overrides=[*QUICK, "train.sdf.init=hull"]).train
    data, _ = load_image_set(decode, gt / "cameras.json", gt / "masks")
    torch.manual_seed(cfg.seed)
    sphere = OrcaModel(model_spec(cfg)).eval()
    sphere_normals, _ = shape_errors(sphere, capture, decode)
    torch.manual_seed(cfg.seed)
    model = OrcaModel(model_spec(cfg))
    start_from_hull(model, data, cfg)
    normals, _ = shape_errors(model.eval(), capture, decode)
    sphere_iou, hull_iou = zero_set_iou(sphere, data), zero_set_iou(model, data)
    print(f"sphere start: {sphere_normals:.1f} deg, silhouette IoU {sphere_iou:.3f}; "
          f"hull start: {normals:.1f} deg, IoU {hull_iou:.3f}")
    assert hull_iou > 0.9 and hull_iou > sphere_iou + 0.1
    assert normals < 0.6 * sphere_normals
