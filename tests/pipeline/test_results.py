"""Loading artifacts for notebooks: the decode folder's images come back as written; every stage of the tiny
capture's results folder loads as its stage wrote it; a stage that has not run is an error naming its folder."""

from __future__ import annotations

import shutil

import numpy as np
import pytest

from pipeline.config import DecodeConfig
from pipeline.errors import InputError
from pipeline.imageio import srgb_to_linear, write_png
from pipeline.layout import STAGES
from pipeline.rendering import render_object_view
from pipeline.results import load_decode, load_poses, load_results, load_train
from pipeline.stages.decode import run_decode
from pipeline.stages.report import run_report


def test_load_decode_returns_each_image(tmp_path):
    cap = tmp_path / "cap"
    rng = np.random.default_rng(0)
    images = {}
    for i in range(3):
        img = rng.integers(0, 200, (12, 16, 3), dtype=np.uint8)  # below 255: nothing clips
        write_png(cap / f"im{i}.png", img)
        images[f"im{i}"] = img
    run_decode(cap, tmp_path / "decode", DecodeConfig())
    dec = load_decode(tmp_path / "decode")
    assert dec.names == ["im0", "im1", "im2"]
    for name, img in images.items():
        np.testing.assert_allclose(dec.linear(name), srgb_to_linear(img / 255.0), atol=1e-6)
        np.testing.assert_array_equal(dec.srgb(name), img)
        assert not dec.clipped(name).any()
    assert dec.manifest["stage"] == "decode"
    with pytest.raises(KeyError, match="im9"):
        dec.linear("im9")
    with pytest.raises(InputError, match="decode.json"):
        load_decode(tmp_path)


# ------------------------------------------------------------------------------ every stage of a results folder


def test_load_results_gives_every_stage_as_the_stages_wrote_it(tiny_results):
    res = load_results(tiny_results)
    assert res.ran() == {**dict.fromkeys(STAGES, True), "report": False}

    # masks: the photo a camera points at is the decoded one here (the tiny capture needs no undistortion)
    names = res.decode.names
    assert res.masks.names == names
    np.testing.assert_array_equal(res.masks.photo(names[1]), res.decode.linear(names[1]))
    with pytest.raises(KeyError, match="IMG_9999"):
        res.masks.photo("IMG_9999")
    assert res.poses.points() is None, "known cameras from a cameras.json: no COLMAP model, no points"

    train = res.train
    iterations = train.report["iterations"]
    curves = train.curves()
    np.testing.assert_array_equal(curves["step"], np.arange(1, iterations + 1))  # log_every=1
    assert {"loss", "psnr_object", "beta", "lr", "mask"} <= set(curves)
    assert all(c.shape == (iterations,) for c in curves.values())
    assert [r["loss"] for r in train.metrics()] == curves["loss"].tolist()
    assert train.checkpoint()["step"] == iterations and train.config.iterations == iterations
    assert [p.name for p in train.checkpoints()] == [f"step_{iterations:07d}.pt"]
    assert [p.name for p in train.previews()] == ["step_0000002.png", "step_0000004.png"]
    assert [c.name for c in train.cameras().cameras] == [c.name for c in res.masks.cameras().cameras]

    # a render at a chosen camera through pipeline.rendering is the export stage's render of that camera
    export = res.export
    name = export.object_names[0]
    model = train.model(device="cpu")
    rendered = render_object_view(model, res.masks.cameras().by_name()[name], export.meta["object_downscale"])
    written = export.object_view(name)
    assert set(written) == {"rgb", "diffuse", "specular", "normal", "depth", "mask"}
    for kind in ("rgb", "diffuse", "specular", "normal"):
        np.testing.assert_allclose(written[kind], rendered[kind], atol=1e-5, err_msg=kind)
    np.testing.assert_array_equal(written["mask"], rendered["mask"])

    mesh, report = res.mesh.mesh(), res.mesh.report
    assert mesh.vertices.shape == (report["vertices"], 3) and mesh.triangles.shape == (report["triangles"], 3)
    assert mesh.colors.shape == mesh.vertices.shape and 0 <= mesh.colors.min() and mesh.colors.max() <= 1
    assert mesh.triangles.max() < len(mesh.vertices)
    to_colmap = np.asarray(res.masks.cameras().frame.to_colmap)
    np.testing.assert_allclose(res.mesh.mesh(colmap=True).vertices, mesh.vertices @ to_colmap[:3, :3].T
                               + to_colmap[:3, 3], atol=1e-5)
    assert len(res.mesh.mesh(max_triangles=300).triangles) <= 300
    assert res.mesh.picture().ndim == 3

    size, width = export.meta["view_size"], export.meta["panorama"]["width"]
    assert export.environment_names == [c.name for c in export.environment_cameras().cameras]
    for view in export.environment_names:
        env = export.environment(view)
        assert env["rgb"].shape == (size, size, 3) and env["depth"].shape == (size, size)
    panorama = export.panorama()
    assert panorama["rgb"].shape == (width // 2, width, 3) and panorama["depth"].shape == (width // 2, width)
    points, colours = export.point_cloud()
    assert points.shape == colours.shape == (export.meta["point_cloud"]["points"], 3)
    np.testing.assert_allclose(export.point_cloud(colmap=True)[0], points @ to_colmap[:3, :3].T + to_colmap[:3, 3],
                               atol=1e-4)
    assert set(export.videos()) == {"orbit", "flythrough"}
    with pytest.raises(KeyError, match="nowhere"):
        export.environment("nowhere")

    evaluation = res.evaluate
    assert evaluation.means("object") == evaluation.results["object"]["mean"]
    view = evaluation.results["object"]["views"][0]
    predicted = evaluation.object_view(view)
    assert predicted["rgb"].shape[:2] == predicted["mask"].shape == predicted["depth"].shape
    env_view = evaluation.results["environment"]["views"][0]
    assert set(evaluation.environment_view(env_view)) == {"rgb", "depth"}
    assert evaluation.grid("object").ndim == evaluation.grid("environment").ndim == 3


def test_a_stage_that_has_not_run_names_its_folder_and_the_fix(tiny_results, tmp_path):
    partial = tmp_path / "tiny"
    for stage in ("decode", "train"):
        shutil.copytree(tiny_results / stage, partial / stage)
    res = load_results(partial)
    assert res.ran() == {**dict.fromkeys(STAGES, False), "decode": True, "train": True, "report": False}
    assert res.train.report["iterations"] > 0
    for stage in ("poses", "masks", "mesh", "export", "report"):
        with pytest.raises(InputError, match=f"the {stage} stage has not run") as e:
            getattr(res, stage)
        assert e.value.path == partial / stage and f"orca {stage}" in e.value.fix
    with pytest.raises(InputError, match="synthetic capture") as e:
        res.stage("evaluate")
    # a stage folder without the file that marks it finished
    (partial / "mesh").mkdir()
    with pytest.raises(InputError, match="not a mesh artifact .no mesh.ply") as e:
        res.stage("mesh")
    assert "orca mesh" in e.value.fix
    with pytest.raises(InputError, match="not a train artifact"):
        load_train(tmp_path)
    # not a results folder
    with pytest.raises(InputError, match="results folder not found"):
        load_results(tmp_path / "nowhere")
    with pytest.raises(InputError, match="not a results folder") as e:
        load_results(partial / "train")
    assert "pass its parent" in e.value.fix

    # once the report has run, its page and manifest
    whole = tmp_path / "whole"
    shutil.copytree(tiny_results, whole)
    run_report(whole)
    report = load_results(whole).report
    assert report.html.is_file() and report.manifest["sections"] == dict.fromkeys(STAGES, "present")


def test_sparse_points_of_a_colmap_model_in_the_cameras_frame(tiny_capture, tiny_decode, tmp_path):
    """The poses stage keeps a capture's COLMAP model and its points; the loader gives them in the normalized
    frame of cameras.json, which its ``to_colmap`` takes back to the model's."""
    from helpers import colmap_model

    from pipeline.cameras import load_cameras
    from pipeline.config import PosesConfig
    from pipeline.signals import import_pycolmap
    from pipeline.stages.poses import run_poses

    capture = tmp_path / "tiny"
    shutil.copytree(tiny_capture, capture)
    model = colmap_model(load_cameras(capture / "ground_truth" / "cameras.json"), capture / "sparse" / "0",
                         points=20)
    run_poses(capture, tiny_decode, tmp_path / "poses", PosesConfig())
    poses = load_poses(tmp_path / "poses")
    points = poses.points()
    assert points is not None and points.xyz.shape == (20, 3)
    given = import_pycolmap().Reconstruction(str(model)).points3D
    to_colmap = np.asarray(poses.cameras().frame.to_colmap)
    back = points.xyz @ to_colmap[:3, :3].T + to_colmap[:3, 3]
    np.testing.assert_allclose(back, [given[i].xyz for i in points.ids], atol=1e-6)
    assert all(len(o) == 4 for o in points.observers)
