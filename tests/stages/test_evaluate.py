"""The evaluate stage. Against a ground truth made from the model's own renders: perfect scores when a result
is compared with itself (also through a frame change that the camera alignment undoes), and the right worse
scores for known perturbations (rotated frame without alignment, noisy normals, a diffuse offset, rotated
cameras, a scaled mesh). End to end: a few training steps on the tiny synthetic capture, then
``run_evaluate`` and ``orca evaluate`` against its ground truth."""

from __future__ import annotations

import json
import math
import shutil
from pathlib import Path

import numpy as np
import pytest
from helpers import TINY_TRAIN, moved_cameras, orbit_cameras, rotation, write_untrained_train_dir

from pipeline.alignment import Similarity
from pipeline.cameras import CameraSet, save_cameras
from pipeline.errors import InputError
from pipeline.imageio import read_exr, read_image, write_exr, write_png
from pipeline.metrics import PSNR_CAP_DB
from pipeline.stages.evaluate import run_evaluate

# --------------------------------------------------------------------------- a result against its own renders

SIM = Similarity(1.7, rotation([1, 2, 3], 40.0), np.array([0.5, -1.0, 2.0]))  # model frame -> "ground truth"


def ground_truth_from_model(train: Path, mesh: Path, out: Path, sim: Similarity | None = None) -> tuple[Path, Path]:
    """A ``ground_truth/`` folder whose images are the model's own renders (``orca render``), its world frame
    the model's moved by ``sim``; and the model-frame cameras.json (the "result's" cameras)."""
    import open3d as o3d

    from pipeline.config import ExportConfig
    from pipeline.panorama import environment_cameras, panorama_frame
    from pipeline.stages.render import run_render

    sim = sim or Similarity(1.0, np.eye(3), np.zeros(3))
    work = out.parent / f"{out.name}_renders"
    cams = orbit_cameras(3, width=48, height=36, prefix="IMG_")
    env = CameraSet(cameras=environment_cameras(ExportConfig(view_size=12, translated_offsets=[0.4],
                                                             rotated_yaw_deg=[]), panorama_frame([0, 0, 1])))
    model_cams = save_cameras(work / "cameras.json", cams)
    save_cameras(work / "env_cameras.json", env)
    run_render(train, model_cams, work / "object", device="cpu")
    run_render(train, work / "env_cameras.json", work / "env", environment=True, device="cpu")
    r, s = sim.rotation, sim.scale
    for cam in cams.cameras:
        n = cam.name
        for part, folder in (("rgb", "linear"), ("diffuse", "diffuse"), ("specular", "specular")):
            write_exr(out / folder / f"{n}.exr", read_exr(work / "object" / f"{n}_{part}.exr"))
        write_exr(out / "normals" / f"{n}.exr", read_exr(work / "object" / f"{n}_normal.exr") @ r.T.astype(np.float32))
        write_exr(out / "depth" / f"{n}.exr", read_exr(work / "object" / f"{n}_depth.exr") * np.float32(s))
        write_png(out / "masks" / f"{n}.png", read_image(work / "object" / f"{n}_mask.png"))
    for cam in env.cameras:
        write_exr(out / "environment" / "rgb" / f"{cam.name}.exr", read_exr(work / "env" / f"{cam.name}_rgb.exr"))
        write_exr(out / "environment" / "depth" / f"{cam.name}.exr",
                  read_exr(work / "env" / f"{cam.name}_depth.exr") * np.float32(s))
    save_cameras(out / "cameras.json", moved_cameras(cams, sim))
    save_cameras(out / "environment" / "cameras.json", moved_cameras(env, sim))
    (out / "scene.json").write_text(json.dumps({
        "radiance_to_decoded": {"factor": 1.0},
        "object": {"centre": sim.translation.tolist(), "radius": 0.7 * s, "mesh": "object.ply"}, "props": []}))
    gt_mesh = o3d.io.read_triangle_mesh(str(mesh))
    gt_mesh.transform(sim.matrix)
    o3d.io.write_triangle_mesh(str(out / "object.ply"), gt_mesh)
    return out, model_cams


@pytest.fixture(scope="module")
def tiny(tmp_path_factory):
    """(train folder, its mesh.ply): an untrained tiny model, meshed at 48^3."""
    from pipeline.config import MeshConfig
    from pipeline.stages.mesh import run_mesh

    root = tmp_path_factory.mktemp("self")
    train = write_untrained_train_dir(root / "train")
    run_mesh(train, root / "mesh", MeshConfig(resolution=48), device="cpu")
    return train, root / "mesh" / "mesh.ply"


def _evaluate(train, gt, out, **kw):
    return run_evaluate(train, gt, out, device="cpu", **kw)


def _assert_perfect(res):
    obj, env = res["object"]["mean"], res["environment"]["mean"]
    assert obj["normal_mae_deg"] < 0.05 and obj["mask_iou"] == 1.0
    for part in ("rgb", "diffuse", "specular"):
        assert obj[f"psnr_{part}"] > 80 and obj[f"ssim_{part}"] > 0.9999, part
    assert obj["depth_absrel"] < 1e-5
    assert env["psnr_all"] > 80 and env["ssim_all"] > 0.9999 and env["depth_absrel"] < 1e-5
    assert res["mesh"]["chamfer_fraction"] < 1e-4 and res["mesh"]["fscore_1pct"] == pytest.approx(1.0)


def test_a_result_compared_with_itself_scores_perfectly(tiny, tmp_path):
    train, mesh = tiny
    gt, cams = ground_truth_from_model(train, mesh, tmp_path / "gt")
    res = _evaluate(train, gt, tmp_path / "ev", cameras=cams, mesh=mesh)
    _assert_perfect(res)
    assert res["object"]["mean"]["psnr_rgb"] == pytest.approx(PSNR_CAP_DB)
    s = res["poses"]["summary"]
    assert s["rotation_deg_max"] < 1e-6 and s["center_max_percent"] < 1e-6 and s["missing"] == 0
    saved = json.loads((tmp_path / "ev" / "evaluate.json").read_text())
    assert saved["poses"]["summary"] == s and saved["mesh"]["chamfer"] == res["mesh"]["chamfer"]


def test_a_moved_frame_is_undone_by_the_camera_alignment_and_costs_dearly_without_it(tiny, tmp_path):
    train, mesh = tiny
    gt, cams = ground_truth_from_model(train, mesh, tmp_path / "gt", SIM)
    res = _evaluate(train, gt, tmp_path / "ev", cameras=cams, mesh=mesh)
    np.testing.assert_allclose(res["to_ground_truth"], SIM.matrix, atol=1e-9)
    _assert_perfect(res)
    assert res["poses"]["summary"]["scale"] == pytest.approx(1.7)

    unaligned = _evaluate(train, gt, tmp_path / "ev2", mesh=mesh, to_ground_truth=np.eye(4))
    obj = unaligned["object"]["mean"]
    assert obj["normal_mae_deg"] > 20 and obj["mask_iou"] < 0.5, obj
    assert unaligned["mesh"]["chamfer_fraction"] > 1.0


def test_noisy_normals_and_a_diffuse_offset_give_the_expected_errors(tiny, tmp_path):
    train, mesh = tiny
    gt, cams = ground_truth_from_model(train, mesh, tmp_path / "gt")
    rng = np.random.default_rng(0)
    tilt, offset = 5.0, 0.01
    for path in sorted((gt / "normals").glob("*.exr")):
        n = read_exr(path).astype(np.float64)
        valid = np.linalg.norm(n, axis=-1) > 1e-6
        # each normal turned by exactly `tilt` degrees about a random axis perpendicular to it
        perp = np.cross(n, rng.normal(size=n.shape))
        perp /= np.maximum(np.linalg.norm(perp, axis=-1, keepdims=True), 1e-12)
        turned = np.cos(np.deg2rad(tilt)) * n + np.sin(np.deg2rad(tilt)) * perp
        write_exr(path, np.where(valid[..., None], turned, 0).astype(np.float32))
    for path in sorted((gt / "diffuse").glob("*.exr")):
        write_exr(path, read_exr(path) + np.float32(offset))
    res = _evaluate(train, gt, tmp_path / "ev", cameras=cams, environment=False)
    obj = res["object"]["mean"]
    assert obj["normal_mae_deg"] == pytest.approx(tilt, abs=0.02)
    assert obj["psnr_diffuse"] == pytest.approx(-20 * math.log10(offset), abs=0.05)  # MSE = offset^2: 40 dB
    assert obj["ssim_diffuse"] < 0.9999
    assert obj["psnr_specular"] > 80 and obj["mask_iou"] == 1.0, "the rest is untouched"


def test_rotated_cameras_show_as_pose_errors_and_a_scaled_mesh_as_chamfer(tiny, tmp_path):
    import open3d as o3d

    train, mesh = tiny
    gt, cams = ground_truth_from_model(train, mesh, tmp_path / "gt")
    # the result's cameras: each turned 2 degrees about its own optical axis (centres unchanged)
    from pipeline.cameras import load_cameras

    result = load_cameras(cams)
    turned = []
    for c in result.cameras:
        c2w = c.c2w.copy()
        c2w[:3, :3] = c2w[:3, :3] @ rotation([0, 0, 1], 2.0)
        turned.append(c.model_copy(update={"camera_to_world": c2w.tolist()}))
    cams2 = save_cameras(tmp_path / "turned.json", CameraSet(cameras=turned))
    bigger = o3d.io.read_triangle_mesh(str(mesh))
    bigger.scale(1.1, center=np.zeros(3))
    mesh2 = tmp_path / "bigger.ply"
    o3d.io.write_triangle_mesh(str(mesh2), bigger)
    res = _evaluate(train, gt, tmp_path / "ev", cameras=cams2, mesh=mesh2, environment=False, views=1)
    s = res["poses"]["summary"]
    assert s["rotation_deg_median"] == pytest.approx(2.0, abs=1e-6) and s["center_max_percent"] < 1e-6
    # a sphere of radius 0.77 against 0.7: 0.07 each way, Chamfer (sum of both means) 0.14 = 0.2 radii
    assert res["mesh"]["chamfer_fraction"] == pytest.approx(0.2, rel=0.02)
    assert res["mesh"]["fscore_5pct"] < 0.05 and res["mesh"]["fscore_1pct"] == pytest.approx(0.0, abs=1e-3)


def test_orca_evaluate_on_a_results_folder(tiny, tmp_path):
    from pipeline.cli import main

    train, mesh = tiny
    gt, cams = ground_truth_from_model(train, mesh, tmp_path / "gt")
    results = tmp_path / "results"
    shutil.copytree(train, results / "train")
    (results / "poses").mkdir(parents=True)
    shutil.copy(cams, results / "poses" / "cameras.json")
    (results / "mesh").mkdir()
    shutil.copy(mesh, results / "mesh" / "mesh.ply")
    assert main(["evaluate", str(results), "--ground-truth", str(gt), "--views", "1", "--no-environment",
                 "--device", "cpu"]) == 0
    saved = json.loads((results / "evaluate" / "evaluate.json").read_text())
    assert saved["alignment"] == "fitted on camera centres" and "mesh" in saved and "poses" in saved
    assert main(["evaluate", str(results), "--ground-truth", str(gt), "--mesh", str(tmp_path / "none.ply"),
                 "--out", str(tmp_path / "x")]) == 2
    assert not (tmp_path / "x").exists()


# ------------------------------------------------------------------------------------------------- end to end

# Four steps, one checkpoint and one preview at the last.
TINY = [*TINY_TRAIN, "train.iterations=4", "train.logging.checkpoint_every=4", "train.logging.preview_every=4",
        "train.logging.log_every=2"]


@pytest.fixture(scope="module")
def tiny_train(tiny_capture, tiny_decode, tmp_path_factory):
    from pipeline.config import load_config
    from pipeline.stages.train import run_train

    gt = tiny_capture / "ground_truth"
    out = tmp_path_factory.mktemp("eval") / "train"
    cfg = load_config(preset="fast", overrides=TINY).train
    assert run_train(tiny_decode, gt / "cameras.json", gt / "masks", out, cfg) is not None
    return out


def test_run_evaluate_end_to_end(tiny_capture, tiny_train, tmp_path):
    from pipeline.evaluation import ENVIRONMENT_METRICS, OBJECT_METRICS
    from pipeline.stages.evaluate import run_evaluate

    gt = tiny_capture / "ground_truth"
    out = tmp_path / "evaluate"
    res = run_evaluate(tiny_train, gt, out, views=1, downscale=2, device="cpu")
    saved = json.loads((out / "evaluate.json").read_text())
    assert saved["object"]["mean"] == res["object"]["mean"]
    (view,) = saved["object"]["views"]
    figures = saved["object"]["per_view"][view]
    for key in OBJECT_METRICS:
        assert figures[key] is not None and math.isfinite(figures[key]), key
    assert 0 <= figures["mask_iou"] <= 1 and 0 <= figures["normal_mae_deg"] <= 180
    assert figures["pixels"]["region"] > 0
    assert "interior" in saved["object"]["region"], "the synthetic ground truth has coverage/: interior region"
    env = saved["environment"]
    assert env["views"] and set(env["per_view"]) == set(env["views"])
    for key in ("psnr", "psnr_srgb", "ssim", "psnr_all", "ssim_all", "depth_absrel", "depth_rmse"):
        assert env["mean"][key] is not None and math.isfinite(env["mean"][key]), key
    assert set(env["mean"]) == set(ENVIRONMENT_METRICS)
    assert sum(v["pixels"]["props"] for v in env["per_view"].values()) > 0, "props are seen from the centre"

    from pipeline.imageio import read_exr, read_image

    h, w = 36 // 2, 48 // 2
    for suffix in ("rgb", "diffuse", "specular", "normal", "depth"):
        assert read_exr(out / f"{view}_{suffix}.exr").shape[:2] == (h, w)
    assert read_image(out / f"{view}_mask.png").shape == (h, w)
    for name in env["views"]:
        assert (out / f"env_{name}_rgb.exr").is_file() and (out / f"env_{name}_depth.exr").is_file()
    for grid in ("object_grid.png", "environment_grid.png", "manifest.json"):
        assert (out / grid).is_file(), grid


def test_cli_evaluate_and_its_errors(tiny_capture, tiny_train, tmp_path):
    from pipeline.cli import main

    gt = tiny_capture / "ground_truth"
    out = tmp_path / "ev"
    assert main(["evaluate", str(tiny_train), "--ground-truth", str(gt), "--out", str(out), "--views", "1",
                 "--downscale", "3", "--no-environment", "--device", "cpu"]) == 0
    saved = json.loads((out / "evaluate.json").read_text())
    assert "environment" not in saved and saved["object"]["downscale"] == 3

    from pipeline.stages.evaluate import run_evaluate

    with pytest.raises(InputError, match=r"model\.pt[\s\S]*orca train"):
        run_evaluate(tmp_path, gt, tmp_path / "x", views=1, downscale=2)
    no_env = tmp_path / "gt_no_env"
    no_env.mkdir()
    for name in ("cameras.json", "scene.json"):
        (no_env / name).write_bytes((gt / name).read_bytes())
    with pytest.raises(InputError, match="--no-environment"):
        run_evaluate(tiny_train, no_env, tmp_path / "x", views=1, downscale=2)
    assert not (tmp_path / "x").exists()
    assert main(["evaluate", str(tiny_train), "--ground-truth", str(no_env), "--out", str(tmp_path / "x")]) == 2
