"""ORCa: from a folder of photos of a glossy object to its mesh, diffuse/specular parts and the 5D radiance
field of its surroundings. One rule per stage, each calling the `orca` CLI (the same typed stage function a
notebook calls), each writing one folder under results/<capture>/ atomically.

    snakemake --cores 2                                   # every capture in config (default: the demo)
    snakemake --cores 2 -n                                # the plan, nothing run
    snakemake --cores 8 --config captures='["mug"]' preset=standard
    snakemake --profile profiles/slurm                    # a Slurm cluster (pip install -e .[cluster])

A synthetic capture (one with ground_truth/) is also evaluated against its ground truth, a real one trained
with train.holdout_every on the photos it held out (orca evaluate --held-out). Last, every capture
gets results/<capture>/report/report.html: one self-contained page of every stage's pictures and figures.

Each rule's params hold a hash of the config values its stage runs with: changing one (an upgrade that changes
a default included) reruns that stage and what follows it.

Config: config/config.yaml, checked against config/schema/config.schema.yaml (every key optional: captures,
captures_dir, results_dir, preset, set, and resources, what the train, export and evaluate jobs ask a cluster
for: gpu, mem_mb, runtime). Threads are fixed per rule; a local run gives a rule at most --cores of them.
"""

import os
import shlex
import sys
from pathlib import Path

from pipeline import layout
from pipeline.cameras import load_cameras
from pipeline.config import stage_config, stage_config_digest
from pipeline.photos import find_photos
from pipeline.results import image_folder
from snakemake.utils import validate

# ------------------------------------------------------------------------------------------------- config

# The `orca` CLI of the environment Snakemake itself runs in (no need for it to be on PATH).
ORCA = f"{shlex.quote(sys.executable)} -m pipeline.cli"

# The workflow's own config file (not the working directory's: --directory points elsewhere); --configfile and
# --config go on top of it. The schema rejects unknown keys and fills in missing ones.
configfile: os.path.join(workflow.basedir, "config", "config.yaml")
validate(config, "config/schema/config.schema.yaml")

CAPTURES = config["captures"]
if isinstance(CAPTURES, str):
    CAPTURES = [CAPTURES]
CAPTURES_DIR = Path(config["captures_dir"])
RESULTS_DIR = Path(config["results_dir"])
PRESET = config["preset"]
# Config overrides for every stage, as `orca <stage> --set`: --config set='["train.iterations=500"]'
OVERRIDES = config["set"]
if isinstance(OVERRIDES, str):
    OVERRIDES = [OVERRIDES]
SET = " ".join(f"--set {shlex.quote(str(o))}" for o in OVERRIDES)
# What the heavy rules ask a cluster for: {"train": {"gpu": 0, "mem_mb": 8000, "runtime": 240}, ...}
RESOURCES = config["resources"]

# Threads per job: Slurm's --cpus-per-task; a local run lowers them to --cores. SfM's threads and the PyTorch
# stages' (training, rendering) make use of a few cores each; the masks' worker processes of one each.
POSES_THREADS = 4
MASKS_THREADS = 8
TORCH_THREADS = 8

# results/<capture>/benchmarks/<stage>.tsv: each job's wall time and memory (Snakemake's benchmark files)
BENCHMARKS = "benchmarks"

# Cheap rules run on the submitting host, not as cluster jobs.
localrules: all, report

for name in CAPTURES:
    if not (CAPTURES_DIR / name).is_dir():
        hint = (" The demo capture is rendered on first use: run scripts/demo.sh, or `orca synth sphere "
                f"{CAPTURES_DIR / name}`." if name == "demo" else "")
        raise ValueError(f"capture folder {CAPTURES_DIR / name} does not exist (config 'captures').{hint}")


def out(stage):
    """A stage's folder of the capture (the wildcard)."""
    return RESULTS_DIR / "{capture}" / stage


def log_of(stage):
    return RESULTS_DIR / "{capture}" / layout.LOGS / f"{stage}.log"


def benchmark_of(stage):
    return RESULTS_DIR / "{capture}" / BENCHMARKS / f"{stage}.tsv"


def has_ground_truth(capture):
    return (CAPTURES_DIR / capture / layout.GROUND_TRUTH / layout.SCENE_JSON).is_file()


def holds_out(capture):
    """Whether training holds photos out (train.holdout_every, from the preset, capture.yaml and --config set):
    a capture without ground truth is then evaluated on them."""
    capture_yaml = CAPTURES_DIR / capture / layout.CAPTURE_YAML
    return stage_config("train", PRESET, None, OVERRIDES, capture_yaml).train.holdout_every > 0


def evaluated(capture):
    """A synthetic capture against its ground truth, a real one on its held-out photos when it has some."""
    return has_ground_truth(capture) or holds_out(capture)


# ---------------------------------------------------------------------------------------- input functions


def photos(wildcards):
    """The capture's photos, as the decode stage finds them: a new or edited photo reruns everything."""
    return [str(p) for p in find_photos(CAPTURES_DIR / wildcards.capture)[1]]


def capture_config(wildcards):
    """The capture's own capture.yaml, when it has one: editing it reruns the stages."""
    path = CAPTURES_DIR / wildcards.capture / layout.CAPTURE_YAML
    return [str(path)] if path.exists() else []


def config_digest(section, reads_capture_yaml=True):
    """The rule's params: a hash of the values its stage runs with, every default filled in. Snakemake reruns
    a rule whose params changed, so an upgrade that changes a default (or an edited preset) reruns the stages
    it touches, which neither the files nor the command line would show."""
    def digest(wildcards):
        capture_yaml = CAPTURES_DIR / wildcards.capture / layout.CAPTURE_YAML if reads_capture_yaml else None
        return stage_config_digest(section, PRESET, OVERRIDES, capture_yaml)
    return digest


def poses_inputs(wildcards):
    """What the poses stage reads from the capture when present: a calibration, its own cameras, masks."""
    capture = CAPTURES_DIR / wildcards.capture
    found = {}
    for key, rel in (("calibration", layout.CALIBRATION), ("cameras", layout.CAMERAS_JSON),
                     ("transforms", layout.TRANSFORMS_JSON), ("llff", layout.POSES_BOUNDS),
                     ("colmap", layout.SPARSE_MODEL), ("nerfstudio_colmap", layout.NERFSTUDIO_MODEL),
                     ("masks", layout.USER_MASKS)):
        if (capture / rel).exists():
            found[key] = str(capture / rel)
    return found


def user_masks(wildcards):
    """The capture's own masks/ folder (the user's masks, for all or some photos), when it has one: the masks
    stage uses them instead of its automatic ones, and editing them reruns it."""
    path = CAPTURES_DIR / wildcards.capture / layout.USER_MASKS
    return {"user_masks": str(path)} if path.is_dir() else {}


def evaluate_inputs(wildcards):
    """The ground truth of a synthetic capture (none for a real one, evaluated on its held-out photos)."""
    path = CAPTURES_DIR / wildcards.capture / layout.GROUND_TRUTH
    return {"ground_truth": str(path)} if has_ground_truth(wildcards.capture) else {}


def evaluate_against(wildcards, input):
    """evaluate's arguments: the ground truth and the mesh, or the held-out photos."""
    if "ground_truth" in input.keys():
        return (f"--ground-truth {input.ground_truth} --mesh {input.mesh}/{layout.MESH_PLY} --views 8 "
                "--downscale 2")
    return "--held-out --downscale 2"


def report_inputs(wildcards):
    """Every stage's folder of the capture, evaluate's only when the capture has ground truth: the report shows
    them all, and is redone when any of them changes."""
    stages = [s for s in layout.STAGES if s != layout.EVALUATE or evaluated(wildcards.capture)]
    return {stage: str(RESULTS_DIR / wildcards.capture / stage) for stage in stages}


# ------------------------------------------------------------------------------------------------- rules


rule all:
    input:
        [expand(out(s), capture=CAPTURES) for s in layout.STAGES if s not in (layout.DECODE, layout.EVALUATE)],
        [RESULTS_DIR / c / layout.EVALUATE for c in CAPTURES if evaluated(c)],
        expand(out(layout.REPORT), capture=CAPTURES),


rule decode:
    """Photos (RAW or JPEG/PNG/TIFF) -> linear exposure-normalized EXR, sRGB PNG, clipped masks."""
    input:
        photos=photos,
        capture_yaml=capture_config,
    params:
        config=config_digest("decode"),
    output:
        directory(out(layout.DECODE)),
    log:
        log_of(layout.DECODE),
    benchmark:
        benchmark_of(layout.DECODE),
    shell:
        "{ORCA} decode {CAPTURES_DIR}/{wildcards.capture} --out {output} --preset {PRESET} {SET} > {log} 2>&1"


rule poses:
    """Decoded photos -> cameras.json in the object-centred unit-sphere frame (pycolmap SfM, or the capture's
    own cameras.json / transforms.json / poses_bounds.npy / COLMAP model), transforms.json, sparse/0/ beside images/,
    poses_report.json, poses.png."""
    input:
        unpack(poses_inputs),
        decode=out(layout.DECODE),
        capture_yaml=capture_config,
    params:
        config=config_digest("poses"),
    output:
        directory(out(layout.POSES)),
    log:
        log_of(layout.POSES),
    benchmark:
        benchmark_of(layout.POSES),
    threads: POSES_THREADS
    shell:
        "{ORCA} poses {CAPTURES_DIR}/{wildcards.capture} --decode {input.decode} --out {output} --preset {PRESET} "
        "--set poses.num_threads={threads} {SET} > {log} 2>&1"


rule masks:
    """Posed photos -> object masks (automatic: unit-sphere prior, support plane, depth sweep, GrabCut and the
    visual hull made to agree; or the user's CAPTURE/masks/ for all or some photos), cameras.json re-normalized
    to the object's tight bounding sphere, overlays, contact sheet, masks_report.json."""
    input:
        unpack(user_masks),
        decode=out(layout.DECODE),
        poses=out(layout.POSES),
        capture_yaml=capture_config,
    params:
        config=config_digest("masks"),
    output:
        directory(out(layout.MASKS)),
    log:
        log_of(layout.MASKS),
    benchmark:
        benchmark_of(layout.MASKS),
    threads: MASKS_THREADS
    shell:
        "{ORCA} masks {CAPTURES_DIR}/{wildcards.capture} --poses {input.poses} --decode {input.decode} "
        "--out {output} --preset {PRESET} --set masks.workers={threads} {SET} > {log} 2>&1"


rule train:
    """Decoded photos + cameras + masks -> the trained model (SDF, diffuse head, environment field). The cameras
    are the masks stage's (the poses stage's, re-normalized so that the object's tight sphere is the unit
    sphere), for real and synthetic captures alike: evaluation aligns them to the ground truth. The images are
    those the cameras point at: the decoded photos, or the poses stage's poses/undistorted/ when it resampled
    them to pinhole. Its sparse points (poses/sparse/) give the environment field sparse depth of the
    surroundings (losses.sparse_depth). Checkpoints go to train.checkpoints/ beside the output, so a killed job
    resumes where it stopped."""
    input:
        decode=out(layout.DECODE),
        poses=out(layout.POSES),
        masks=out(layout.MASKS),
        capture_yaml=capture_config,
    params:
        config=config_digest("train"),
    output:
        directory(out(layout.TRAIN)),
    log:
        log_of(layout.TRAIN),
    benchmark:
        benchmark_of(layout.TRAIN),
    threads: TORCH_THREADS
    resources:
        **RESOURCES[layout.TRAIN],
    run:
        cameras = Path(input.masks) / layout.CAMERAS_JSON
        images = os.path.relpath(image_folder(load_cameras(cameras), cameras.parent, Path(input.decode)))
        sparse = Path(input.poses) / layout.SPARSE
        points = f"--points {sparse}" if sparse.is_dir() else ""
        shell("{ORCA} train --decode {images} --cameras {cameras} --masks {input.masks}/{layout.MASK_FILES} {points} "
              "--capture {CAPTURES_DIR}/{wildcards.capture} --out {output} --preset {PRESET} {SET} > {log} 2>&1")


rule mesh:
    """The trained SDF -> mesh.ply (open3d marching cubes, diffuse-head vertex colours; mesh_colmap.ply when the
    cameras record to_colmap), mesh_report.json, mesh.png."""
    input:
        train=out(layout.TRAIN),
        masks=out(layout.MASKS),
    params:
        config=config_digest("mesh", reads_capture_yaml=False),
    output:
        directory(out(layout.MESH)),
    log:
        log_of(layout.MESH),
    benchmark:
        benchmark_of(layout.MESH),
    shell:
        "{ORCA} mesh {input.train} --cameras {input.masks}/{layout.CAMERAS_JSON} --out {output} --preset {PRESET} "
        "{SET} > {log} 2>&1"


rule export:
    """The trained model -> environment views + depth (EXR + PNG) from virtual cameras at the object, an
    equirectangular panorama + depth, the environment as a point cloud, orbit and flythrough videos (MP4),
    object renders (combined, diffuse, specular, normals). Rendering uses every core."""
    input:
        train=out(layout.TRAIN),
        masks=out(layout.MASKS),
    params:
        config=config_digest("export", reads_capture_yaml=False),
    output:
        directory(out(layout.EXPORT)),
    log:
        log_of(layout.EXPORT),
    benchmark:
        benchmark_of(layout.EXPORT),
    threads: TORCH_THREADS
    resources:
        **RESOURCES[layout.EXPORT],
    shell:
        "{ORCA} export {input.train} --cameras {input.masks}/{layout.CAMERAS_JSON} --out {output} --preset {PRESET} "
        "{SET} > {log} 2>&1"


rule evaluate:
    """A synthetic capture's trained model against its ground truth: camera alignment and pose errors, the
    mesh's Chamfer distance, normals, diffuse / specular / combined, environment views and their depth (8
    object views at half size keep it minutes on a CPU). A real capture trained with train.holdout_every: the
    held-out photos against the model's renders of their cameras."""
    input:
        unpack(evaluate_inputs),
        train=out(layout.TRAIN),
        masks=out(layout.MASKS),
        mesh=out(layout.MESH),
    params:
        against=evaluate_against,
    output:
        directory(out(layout.EVALUATE)),
    log:
        log_of(layout.EVALUATE),
    benchmark:
        benchmark_of(layout.EVALUATE),
    threads: TORCH_THREADS
    resources:
        **RESOURCES[layout.EVALUATE],
    shell:
        "{ORCA} evaluate {input.train} {params.against} --cameras {input.masks}/{layout.CAMERAS_JSON} "
        "--out {output} > {log} 2>&1"


rule report:
    """Every stage's folder -> report/report.html: one self-contained page (pictures embedded, no network) with
    each stage's figures and pictures, training curves, the environment panorama, and the evaluation when there
    is one. Cheap: seconds."""
    input:
        unpack(report_inputs),
    output:
        directory(out(layout.REPORT)),
    log:
        log_of(layout.REPORT),
    benchmark:
        benchmark_of(layout.REPORT),
    shell:
        "{ORCA} report {RESULTS_DIR}/{wildcards.capture} --out {output} > {log} 2>&1"
