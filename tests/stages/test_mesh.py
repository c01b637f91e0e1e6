"""The mesh stage: ``orca mesh`` on a tiny untrained model (its SDF: the initial sphere) writes a watertight,
coloured mesh.ply in the model's frame and in COLMAP's, and refuses a folder without a model."""

from __future__ import annotations

import json

import numpy as np
import pytest
from helpers import orbit_cameras, write_untrained_train_dir

from pipeline.cameras import CameraSet, save_cameras
from pipeline.cli import main
from pipeline.errors import InputError
from pipeline.stages.mesh import run_mesh


def test_orca_mesh_on_a_tiny_model(tmp_path):
    import open3d as o3d

    to_colmap = np.diag([2.0, 2.0, 2.0, 1.0])
    to_colmap[:3, 3] = [1.0, 0.0, -1.0]
    cams = orbit_cameras(3)
    cameras = save_cameras(tmp_path / "cameras.json", CameraSet(frame={"to_colmap": to_colmap.tolist()},
                                                                 cameras=cams.cameras))
    train = write_untrained_train_dir(tmp_path / "train", cameras=cameras)
    out = tmp_path / "mesh"
    assert main(["mesh", str(train), "--out", str(out), "--resolution", "40", "--device", "cpu"]) == 0
    report = json.loads((out / "mesh_report.json").read_text())
    assert report["resolution"] == 40 and report["watertight"] and report["triangles"] > 1000
    mesh = o3d.io.read_triangle_mesh(str(out / "mesh.ply"))
    v = np.asarray(mesh.vertices)
    assert len(v) == report["vertices"] and mesh.has_vertex_colors() and mesh.has_vertex_normals()
    r = np.linalg.norm(v, axis=1)
    assert np.abs(r - 0.7).max() < 0.05, "the untrained SDF is the initial sphere plus a small correction"
    colors = np.asarray(mesh.vertex_colors)
    assert colors.min() >= 0 and colors.max() <= 1 and colors.std() < 0.2  # the untrained diffuse head: ~constant
    colmap = np.asarray(o3d.io.read_triangle_mesh(str(out / "mesh_colmap.ply")).vertices)
    np.testing.assert_allclose(colmap, 2 * v + [1.0, 0.0, -1.0], atol=1e-5)
    assert (out / "mesh.png").is_file() and (out / "manifest.json").is_file()

    with pytest.raises(InputError, match="orca train"):
        (tmp_path / "untrained").mkdir()
        run_mesh(tmp_path / "untrained", tmp_path / "nothing")
    assert not (tmp_path / "nothing").exists()
