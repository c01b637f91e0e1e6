"""Where everything lives: the capture folder's names, the stages in DAG order, and every artifact's path
and file name. Stages, the Snakefile and the loaders (:mod:`pipeline.results`) spell names only through here.

    captures/<capture>/             photos (or images/), capture.yaml, masks/, calibration/, cameras.json,
                                    transforms.json, poses_bounds.npy, sparse/0/ or colmap/sparse/0/ (known
                                    cameras), ground_truth/ (synthetic)
    results/<capture>/<stage>/      one folder per stage, written atomically, each with manifest.json
"""

from __future__ import annotations

from pathlib import Path

# ------------------------------------------------------------------------------------------- the capture

PHOTO_SUBDIR = "images"  # when present, the photos are there and nowhere else
CAPTURE_YAML = "capture.yaml"
CAPTURE_CONFIGS = (CAPTURE_YAML, "capture.yml")
USER_MASKS = "masks"  # <photo name>.png, white = object
CALIBRATION = Path("calibration") / "calibration.json"  # `orca calibrate`
GROUND_TRUTH = "ground_truth"
SCENE_JSON = "scene.json"  # in ground_truth/: marks a synthetic capture

# ------------------------------------------------------------------------------------------- the stages

RESULTS = Path("results")
DECODE, POSES, MASKS, TRAIN, MESH, EXPORT, EVALUATE, REPORT = (
    "decode", "poses", "masks", "train", "mesh", "export", "evaluate", "report")
STAGES = (DECODE, POSES, MASKS, TRAIN, MESH, EXPORT, EVALUATE)  # DAG order; the report shows them all
LOGS = "logs"  # results/<capture>/logs/<stage>.log (the Snakefile's)

MANIFEST = "manifest.json"  # in every stage folder

# ------------------------------------------------------------------------------------------- artifacts

# decode (and poses/undistorted/, a folder in decode's layout)
DECODE_JSON = "decode.json"
IMAGE_KINDS = LINEAR, SRGB, CLIPPED = ("linear", "srgb", "clipped")  # a folder each; decode.json records each
# image's three files

# poses
CAMERAS_JSON = "cameras.json"  # also a capture's known cameras, and masks' re-normalized cameras
TRANSFORMS_JSON = "transforms.json"  # nerfstudio's, in the frame of the cameras.json beside it
TRANSFORMS_COLMAP_JSON = "transforms_colmap.json"  # the masks stage's second one, in COLMAP's frame
SPARSE_PLY, SPARSE_PLY_COLMAP = "sparse_pc.ply", "sparse_pc_colmap.ply"  # the sparse points for those files
POSES_BOUNDS, LLFF_IMAGE_NAMES = "poses_bounds.npy", "all_image_names.txt"  # LLFF known cameras (pipeline.llff)
SPARSE = "sparse"  # COLMAP's folder of models; ours is its model "0" (SPARSE_MODEL), beside COLMAP_IMAGES
SPARSE_MODEL = f"{SPARSE}/0"  # COLMAP binary model: cameras.bin, images.bin, points3D.bin (+ rigs, frames)
COLMAP_IMAGES = "images"  # 8-bit PNGs named as in images.bin, where 3DGS, gsplat, nerfstudio, OpenMVS look
NERFSTUDIO_MODEL = "colmap/sparse/0"  # a capture's COLMAP model as nerfstudio's ns-process-data lays it out
SFM_DATABASE = "database.db"  # COLMAP's, kept with poses.keep_database
UNDISTORTED = "undistorted"
POSES_REPORT = "poses_report.json"
POSES_FIGURE = "poses.png"

# masks (and cameras.json)
MASK_FILES = "masks"  # <name>.png, 0/255 at the image's full size
MASKS_REPORT = "masks_report.json"
OVERLAYS = "overlays"
CONTACT_SHEET = "contact_sheet.jpg"

# train (and its live copies in train.checkpoints/: metrics, previews, tensorboard events as "tb")
MODEL = "model.pt"
CHECKPOINTS_SUFFIX = ".checkpoints"  # train.checkpoints/ beside the train folder
TRAIN_CONFIG = "config.json"
TRAIN_REPORT = "train_report.json"
METRICS = "metrics.jsonl"
PREVIEWS = "previews"
TENSORBOARD = "tensorboard"
LIVE_TENSORBOARD = "tb"

# mesh
MESH_PLY = "mesh.ply"
MESH_COLMAP_PLY = "mesh_colmap.ply"
MESH_REPORT = "mesh_report.json"
MESH_FIGURE = "mesh.png"

# export (and render: views.json beside the rendered images)
EXPORT_JSON = "export.json"
PANORAMA = "panorama"
ENVIRONMENT = "environment"  # also ground_truth/environment/
OBJECT_VIEWS = "object"
VIDEOS = "videos"
ORBIT_VIDEO, FLYTHROUGH_VIDEO = "orbit.mp4", "flythrough.mp4"
POINT_CLOUD, POINT_CLOUD_COLMAP = "environment_points.ply", "environment_points_colmap.ply"
OVERVIEW = "overview.png"
VIEWS_JSON = "views.json"

# evaluate, report
EVALUATE_JSON = "evaluate.json"
OBJECT_GRID, ENVIRONMENT_GRID = "object_grid.png", "environment_grid.png"
HELD_OUT_GRID = "held_out_grid.png"  # evaluate --held-out: photo | render | error of each held-out photo
REPORT_HTML = "report.html"


def stage_dir(capture: str | Path, stage: str, given: str | Path | None = None) -> Path:
    """A stage's folder: ``given`` when set, else ``results/<capture folder name>/<stage>`` (the CLI default,
    the Snakefile's layout)."""
    return Path(given) if given is not None else RESULTS / Path(capture).resolve().name / stage


def decoded_files(name: str) -> dict[str, str]:
    """A decoded image's files, relative to its decode-style folder, as decode.json records them."""
    return {LINEAR: f"{LINEAR}/{name}.exr", SRGB: f"{SRGB}/{name}.png", CLIPPED: f"{CLIPPED}/{name}.png"}


def mask_file(name: str) -> str:
    """A mask, relative to the masks stage's folder."""
    return f"{MASK_FILES}/{name}.png"
