"""Do nerfstudio's own data parser and dataset read the transforms.json files the poses and masks stages write?

Two steps, in two environments (nerfstudio pins its own torch, opencv and numpy):

    .venv/bin/python bench/nerfstudio_check.py make /tmp/ns_check    # this package: synthetic capture, SfM, masks
    NSENV/bin/python bench/nerfstudio_check.py check /tmp/ns_check   # nerfstudio's parser on the three files

``make`` renders the glossy sphere (20 JPEG photos at 320x240), decodes it, poses it by SfM (real sparse points) and
runs the masks stage with the ground-truth masks as the user's. ``check`` reads ``masks/transforms.json`` (the frame
training uses), ``masks/transforms_colmap.json`` and ``poses/transforms.json`` with
``NerfstudioDataParserConfig(data=FILE, eval_mode="all").setup().get_dataparser_outputs("train")`` and
``InputDataset``, and measures: every image as nerfstudio's dataset loads it is 8-bit at the cameras' size, every
mask is read (and what share of pixels it keeps), the points loaded from ``ply_file_path``, and that in nerfstudio's
own re-oriented, re-scaled frame its points project through its cameras to where the file's points project through
the file's cameras (pixels; and the same with the other frame's PLY, which must fail: the check can tell frames
apart). ``dataparser_transform`` x ``dataparser_scale`` applied to the COLMAP-frame points must give nerfstudio's
points (``applied_transform`` is right). Prints a table and writes ``bench/results/nerfstudio_check.json``.
"""

from __future__ import annotations

import argparse
import json
import platform
import sys
from importlib import metadata
from pathlib import Path

import numpy as np

RESULTS = Path(__file__).resolve().parent / "results" / "nerfstudio_check.json"
FILES = (("masks", "transforms.json", "sparse_pc_colmap.ply"), ("masks", "transforms_colmap.json", "sparse_pc.ply"),
         ("poses", "transforms.json", None))
OPENGL_TO_OPENCV = np.diag([1.0, -1.0, -1.0, 1.0])
# pass marks: nerfstudio computes in float32; the wrong frame's PLY lands pixels away
MAX_PX, MAX_REL, CONTROL_PX = 1e-2, 1e-5, 1.0


def make(out: Path) -> None:
    """The capture and the decode, poses and masks stages' folders under ``out`` (this package's environment)."""
    from pipeline.config import DecodeConfig, MasksConfig, PosesConfig
    from pipeline.stages.decode import run_decode
    from pipeline.stages.masks import run_masks
    from pipeline.stages.poses import run_poses
    from pipeline.synth import SCENES, SynthOptions, render_capture

    options = SynthOptions(views=20, width=320, height=240, spp=8, format="jpg", env_size=16, coverage_spp=4, seed=0)
    capture = render_capture(SCENES["sphere"], out / "capture", options)
    run_decode(capture, out / "decode", DecodeConfig())
    run_poses(capture, out / "decode", out / "poses", PosesConfig(num_threads=2))
    run_masks(capture, out / "poses", out / "masks", MasksConfig(), user_masks_dir=capture / "ground_truth" / "masks")
    print(f"made {out}: capture, decode, poses, masks")


def _project(c2w_opengl: np.ndarray, K: np.ndarray, xyz: np.ndarray) -> np.ndarray:
    """Pixels ``(M, 2)`` of points ``(M, 3)`` seen by an OpenGL camera-to-world ``(3|4, 4)``; NaN behind it."""
    c2w = np.eye(4)
    c2w[: len(c2w_opengl)] = c2w_opengl
    w2c = np.linalg.inv(c2w @ OPENGL_TO_OPENCV)
    cam = xyz @ w2c[:3, :3].T + w2c[:3, 3]
    uvw = cam @ K.T
    uv = uvw[:, :2] / uvw[:, 2:]
    uv[cam[:, 2] <= 0] = np.nan
    return uv


def _read_ply(path: Path) -> np.ndarray:
    import open3d as o3d

    return np.asarray(o3d.io.read_point_cloud(str(path)).points, np.float64)


def check_file(folder: Path, name: str, other_ply: str | None, colmap_points: np.ndarray | None) -> dict:
    """nerfstudio's parser and dataset on one file; see the module doc."""
    from nerfstudio.data.dataparsers.nerfstudio_dataparser import NerfstudioDataParserConfig
    from nerfstudio.data.datasets.base_dataset import InputDataset

    path = folder / name
    doc = json.loads(path.read_text())
    # load_3D_points as splatfacto's method config sets it (the parser's default is off)
    config = NerfstudioDataParserConfig(data=path, eval_mode="all", load_3D_points=True)
    outputs = config.setup().get_dataparser_outputs("train")
    dataset = InputDataset(outputs)
    row: dict = {"file": str(path.relative_to(folder.parent)), "frames": len(doc["frames"]),
                 "parsed_images": len(outputs.image_filenames)}
    dtypes, sizes_ok, kept = set(), True, []
    cams = outputs.cameras
    for i in range(len(dataset)):
        image = dataset.get_numpy_image(i)
        dtypes.add(str(image.dtype))
        sizes_ok &= image.shape[:2] == (int(cams.height[i]), int(cams.width[i]))
        item = dataset[i]
        if "mask" in item:
            kept.append(float(item["mask"].float().mean()))
    row.update({"image_dtypes": sorted(dtypes), "image_sizes_match_cameras": bool(sizes_ok),
                "masks": len(kept), "mask_kept_share_median": float(np.median(kept)) if kept else None})

    meta = outputs.metadata
    if "points3D_xyz" not in meta:
        row["points"] = 0
        return row
    ns_xyz = meta["points3D_xyz"].numpy().astype(np.float64)
    file_xyz = _read_ply(folder / doc["ply_file_path"])
    row["points"] = len(ns_xyz)
    # nerfstudio's frame (its cameras and points) against the file's own (the json's cameras and the PLY)
    by_name = {Path(f["file_path"]).name: f for f in doc["frames"]}
    errors, control = [], []
    other = _read_ply(folder / other_ply) if other_ply else None
    for i, image in enumerate(outputs.image_filenames):
        frame = by_name[Path(image).name]
        K_file = np.array([[doc["fl_x"], 0, doc["cx"]], [0, doc["fl_y"], doc["cy"]], [0, 0, 1]])
        K_ns = np.array([[float(cams.fx[i]), 0, float(cams.cx[i])], [0, float(cams.fy[i]), float(cams.cy[i])],
                         [0, 0, 1]])
        ns_uv = _project(cams.camera_to_worlds[i].numpy().astype(np.float64), K_ns, ns_xyz)
        file_uv = _project(np.asarray(frame["transform_matrix"]), K_file, file_xyz)
        inside = np.all((file_uv >= 0) & (file_uv < [doc["w"], doc["h"]]), axis=1)  # NaN (behind) compares False
        errors.append(np.max(np.linalg.norm(ns_uv - file_uv, axis=1)[inside]))
        if other is not None:
            control.append(np.nanmedian(np.linalg.norm(_project(np.asarray(frame["transform_matrix"]), K_file, other)
                                                       - file_uv, axis=1)))
    row["reprojection_px_max"] = float(np.max(errors))  # over the points inside each image
    if control:
        row["other_frame_ply_px_median"] = float(np.median(control))
    if colmap_points is not None:  # applied_transform: nerfstudio's dataparser_transform starts in COLMAP's frame
        m = outputs.dataparser_transform.numpy().astype(np.float64)
        mapped = outputs.dataparser_scale * (colmap_points @ m[:, :3].T + m[:, 3])
        from scipy.spatial import cKDTree  # the poses stage's PLY lists the points in another order

        gap = cKDTree(mapped).query(ns_xyz)[0]
        row["colmap_to_nerfstudio_max_error"] = float(gap.max() / np.ptp(ns_xyz, axis=0).max())
    return row


def check(out: Path) -> dict:
    import torch

    versions = {p: _version(p) for p in ("nerfstudio", "torch", "torchvision", "numpy", "opencv-python-headless",
                                         "opencv-contrib-python-headless", "pillow", "open3d", "gsplat", "pycolmap",
                                         "orca-capture")}
    colmap_points = _read_ply(out / "masks" / "sparse_pc_colmap.ply")
    rows = [check_file(out / stage, name, other, colmap_points) for stage, name, other in FILES]
    result = {"python": platform.python_version(), "versions": versions, "cuda": torch.cuda.is_available(),
              "results": str(out), "files": rows}
    for r in rows:
        print(json.dumps(r))
    ok = all(r["image_dtypes"] == ["uint8"] and r["image_sizes_match_cameras"] and r["parsed_images"] == r["frames"]
             and r["points"] > 0 and r["reprojection_px_max"] < MAX_PX and r["colmap_to_nerfstudio_max_error"] < MAX_REL
             for r in rows)
    ok &= all(r["masks"] == r["frames"] and r["other_frame_ply_px_median"] > CONTROL_PX for r in rows[:2])
    result["ok"] = bool(ok)
    RESULTS.parent.mkdir(parents=True, exist_ok=True)
    RESULTS.write_text(json.dumps(result, indent=2) + "\n")
    print(f"{'OK' if ok else 'FAILED'}; versions {versions}; written {RESULTS}")
    return result


def _version(name: str) -> str:
    try:
        return metadata.version(name)
    except metadata.PackageNotFoundError:
        return "not installed"


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("step", choices=("make", "check"))
    parser.add_argument("out", type=Path)
    args = parser.parse_args()
    if args.step == "make":
        make(args.out)
        return 0
    return 0 if check(args.out)["ok"] else 1


if __name__ == "__main__":
    sys.exit(main())
