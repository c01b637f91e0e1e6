"""``orca mesh``: the trained SDF's zero level set as a triangle mesh (open3d marching cubes).

The SDF is sampled on a grid of ``mesh.resolution`` voxels per side over the cube ``[-extent, extent]^3``
(default: the SDF network's own bound, the region it models), only near the surface unless
``mesh.sparse=false``; outside the cube the shape is closed by its faces (see :mod:`pipeline.meshing`).

After marching cubes, connected pieces with fewer triangles than ``mesh.min_component_fraction`` of the
largest are dropped (floaters of a learned SDF). Vertex colours come from the diffuse head at the vertices,
tone-mapped to sRGB (linear radiance, 1 decoded unit = white).

Writes ``OUT/`` atomically: ``mesh.ply`` (the model's frame: the normalized frame of ``cameras.json``, the
object's bounding sphere is the unit sphere), ``mesh_colmap.ply`` when the cameras' frame records
``to_colmap``, ``mesh_report.json``, ``mesh.png`` (three shaded views, ray cast with open3d), ``manifest.json``.
"""

from __future__ import annotations

import argparse
import logging
import time
from pathlib import Path
from typing import Any

import numpy as np

from ..artifacts import atomic_dir, check_output_dir, write_json, write_manifest
from ..config import MeshConfig, add_config_arguments, config_from_arguments, with_values
from ..imageio import linear_to_srgb
from ..layout import MESH_COLMAP_PLY, MESH_FIGURE, MESH_PLY, MESH_REPORT
from ..meshing import (
    diffuse_colors,
    drop_small_components,
    marching_cubes,
    mesh_picture,
    mesh_properties,
    model_sdf,
    to_open3d,
)
from ..model_io import model_file, training_cameras
from ..provenance import common_capture
from ..rendering import load_renderer

log = logging.getLogger("orca.mesh")



def run_mesh(train_dir: Path, out_dir: Path, cfg: MeshConfig | None = None, *, cameras: Path | None = None,
             device: str = "auto") -> dict[str, Any]:
    """Mesh the SDF of ``train_dir``'s model into ``out_dir`` (atomically); returns ``mesh_report.json``."""
    started = time.time()
    cfg = cfg if cfg is not None else MeshConfig()
    train_dir, out_dir = Path(train_dir), Path(out_dir)
    sources = [train_dir, *([cameras] if cameras else [])]
    check_output_dir(out_dir, "mesh", sources)
    capture = common_capture(sources, force=True)  # --cameras of another capture: only the frame is taken from it
    weights = model_file(train_dir)
    camera_set, cams_from = training_cameras(train_dir, cameras)
    if camera_set is None:
        log.info("no COLMAP-frame mesh: no training cameras (%s)", cams_from)
    model = load_renderer(train_dir, device)
    extent = cfg.extent if cfg.extent is not None else float(model.sdf_field.spec.bound)
    log.info("mesh: %s at %d^3 over [-%.3g, %.3g]^3 (voxel %.4g)", train_dir, cfg.resolution, extent, extent,
             2 * extent / cfg.resolution)
    vertices, triangles, stats = marching_cubes(model_sdf(model, cfg.chunk), extent, cfg.resolution,
                                                block_resolution=cfg.block_resolution, sparse=cfg.sparse,
                                                chunk=cfg.chunk)
    colors = linear_to_srgb(diffuse_colors(model, vertices, cfg.chunk)) if cfg.colors and len(vertices) else None
    mesh = to_open3d(vertices, triangles, colors)
    cleaning = drop_small_components(mesh, cfg.min_component_fraction)
    props = mesh_properties(mesh)
    if props["triangles"] == 0:
        log.warning("the mesh is empty: the SDF never crosses zero inside the cube (is the model trained?)")
    elif not props["watertight"]:
        log.warning("the mesh is not watertight (holes or non-manifold edges)")
    report: dict[str, Any] = {
        "train": str(train_dir), "resolution": cfg.resolution, "extent": extent, **stats, **cleaning, **props,
        "frame": "the model's normalized frame (object bounding sphere = unit sphere)",
        "colors": "diffuse head at the vertices, srgb(clip(linear, 0, 1))" if colors is not None else None,
    }
    import open3d as o3d

    with atomic_dir(out_dir, "mesh", sources) as tmp:
        o3d.io.write_triangle_mesh(str(tmp / MESH_PLY), mesh, write_ascii=False)
        to_colmap = camera_set.frame.to_colmap if camera_set is not None else None
        if to_colmap is not None:
            colmap = o3d.geometry.TriangleMesh(mesh)
            colmap.transform(np.asarray(to_colmap, np.float64))
            o3d.io.write_triangle_mesh(str(tmp / MESH_COLMAP_PLY), colmap, write_ascii=False)
            report["colmap_mesh"] = MESH_COLMAP_PLY
        mesh_picture(mesh, tmp / MESH_FIGURE)
        report["seconds_total"] = round(time.time() - started, 2)
        write_json(tmp / MESH_REPORT, report)
        write_manifest(tmp, stage="mesh", inputs={"model": weights}, config=cfg.model_dump(), started=started,
                       capture=capture)
    log.info("mesh: %d vertices, %d triangles, %s, %d piece(s) kept of %d -> %s (%.1f s)", props["vertices"],
             props["triangles"], "watertight" if props.get("watertight") else "NOT watertight",
             cleaning["components_kept"], cleaning["components"], out_dir, time.time() - started)
    return report


# -------------------------------------------------------------------------------------------------- CLI

EPILOG = """\
examples:
  orca mesh results/demo/train                         -> results/demo/mesh/mesh.ply, mesh_report.json
  orca mesh results/demo/train --resolution 512 --out /tmp/fine_mesh
  orca mesh results/demo/train --set mesh.sparse=false  sample every voxel (slower, same mesh)
"""


def register(subparsers: Any) -> None:
    p = subparsers.add_parser(
        "mesh", help="trained SDF -> mesh.ply (open3d marching cubes, diffuse vertex colours)",
        description=__doc__, epilog=EPILOG, formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("train", type=Path, help="train stage folder (with model.pt)")
    p.add_argument("--out", type=Path, default=None, help="output folder (default: mesh/ beside TRAIN)")
    p.add_argument("--resolution", type=int, default=None, help="voxels per side (overrides mesh.resolution)")
    p.add_argument("--cameras", type=Path, default=None,
                   help="the cameras.json the model was trained with (its frame's to_colmap gives mesh_colmap.ply; "
                        "default: as the train manifest records)")
    p.add_argument("--device", choices=["auto", "cpu", "cuda"], default="auto")
    add_config_arguments(p)
    p.set_defaults(func=main)


def main(args: argparse.Namespace) -> dict[str, Any]:
    cfg = config_from_arguments(args, "mesh").mesh
    if args.resolution is not None:
        cfg = with_values(cfg, f"--resolution {args.resolution}", resolution=args.resolution)
    train = Path(args.train)
    out = args.out if args.out is not None else train.parent / "mesh"
    return run_mesh(train, out, cfg, cameras=args.cameras, device=args.device)
