"""ORCa: from a folder of photos of a glossy object to its mesh, diffuse/specular parts and the 5D radiance
field of its surroundings. One rule per stage, each calling the `orca` CLI (the same typed stage function a
notebook calls), each writing one folder under results/<capture>/ atomically.

    snakemake --cores 2                                   # every capture in config (default: the demo)
    snakemake --cores 2 -n                                # the plan, nothing run
    snakemake --cores 8 --config captures='["mug"]' preset=standard
    snakemake --executor slurm ...                        # a cluster, through an executor plugin

A synthetic capture (one with ground_truth/) is also evaluated against its ground truth. Last, every capture
gets results/<capture>/report/report.html: one self-contained page of every stage's pictures and figures.

Each rule's params hold a hash of the config values its stage runs with: changing one (an upgrade that changes
a default included) reruns that stage and what follows it.

Config keys (all optional): captures (list of folder names under captures_dir), captures_dir, results_dir,
preset (fast | standard | paper), set (a list of config overrides, e.g. '["train.iterations=500"]').
"""

import shlex
import sys
from pathlib import Path

from pipeline.config import PRESETS, stage_config_digest
from pipeline.stages.decode import find_photos

# The `orca` CLI of the environment Snakemake itself runs in (no need for it to be on PATH).
ORCA = f"{shlex.quote(sys.executable)} -m pipeline.cli"

KNOWN_KEYS = {"captures", "captures_dir", "results_dir", "preset", "set"}
unknown = set(config) - KNOWN_KEYS
if unknown:
    raise ValueError(f"unknown Snakemake config key(s) {sorted(unknown)}; known: {sorted(KNOWN_KEYS)}")

CAPTURES = config.get("captures", ["demo"])
if isinstance(CAPTURES, str):
    CAPTURES = [CAPTURES]
CAPTURES_DIR = Path(config.get("captures_dir", "captures"))
RESULTS_DIR = Path(config.get("results_dir", "results"))
PRESET = config.get("preset", "fast")
# Config overrides for every stage, as `orca <stage> --set`: --config set='["train.iterations=500"]'
OVERRIDES = config.get("set", [])
if isinstance(OVERRIDES, str):
    OVERRIDES = [OVERRIDES]
SET = " ".join(f"--set {shlex.quote(str(o))}" for o in OVERRIDES)
if PRESET not in PRESETS:
    raise ValueError(f"unknown preset {PRESET!r}; choose one of {', '.join(PRESETS)}")

for name in CAPTURES:
    if not (CAPTURES_DIR / name).is_dir():
        hint = (" The demo capture is rendered on first use: run scripts/demo.sh, or `orca synth sphere "
                f"{CAPTURES_DIR / name}`." if name == "demo" else "")
        raise ValueError(f"capture folder {CAPTURES_DIR / name} does not exist (config 'captures').{hint}")


def capture_config(wildcards):
    """The capture's own capture.yaml, when it has one: editing it reruns the stages."""
    path = CAPTURES_DIR / wildcards.capture / "capture.yaml"
    return [str(path)] if path.exists() else []


def config_digest(section, reads_capture_yaml=True):
    """The rule's params: a hash of the values its stage runs with, every default filled in. Snakemake reruns
    a rule whose params changed, so an upgrade that changes a default (or an edited preset) reruns the stages
    it touches, which neither the files nor the command line would show."""
    def digest(wildcards):
        capture_yaml = CAPTURES_DIR / wildcards.capture / "capture.yaml" if reads_capture_yaml else None
        return stage_config_digest(section, PRESET, OVERRIDES, capture_yaml)
    return digest


def user_masks(wildcards):
    """The capture's own masks/ folder (the user's masks, for all or some photos), when it has one: the masks
    stage uses them instead of its automatic ones, and editing them reruns it."""
    path = CAPTURES_DIR / wildcards.capture / "masks"
    return {"user_masks": str(path)} if path.is_dir() else {}


def poses_inputs(wildcards):
    """What the poses stage reads from the capture when present: a calibration, its own cameras, masks."""
    capture = CAPTURES_DIR / wildcards.capture
    found = {}
    for key, rel in (("calibration", "calibration/calibration.json"), ("cameras", "cameras.json"),
                     ("transforms", "transforms.json"), ("masks", "masks")):
        if (capture / rel).exists():
            found[key] = str(capture / rel)
    return found


def has_ground_truth(capture):
    return (CAPTURES_DIR / capture / "ground_truth" / "scene.json").is_file()


REPORTED_STAGES = ["decode", "poses", "masks", "train", "mesh", "export"]


def report_inputs(wildcards):
    """Every stage's folder of the capture, evaluate's only when the capture has ground truth: the report shows
    them all, and is redone when any of them changes."""
    stages = REPORTED_STAGES + (["evaluate"] if has_ground_truth(wildcards.capture) else [])
    return {stage: str(RESULTS_DIR / wildcards.capture / stage) for stage in stages}


rule all:
    input:
        expand(RESULTS_DIR / "{capture}" / "poses", capture=CAPTURES),
        expand(RESULTS_DIR / "{capture}" / "masks", capture=CAPTURES),
        expand(RESULTS_DIR / "{capture}" / "train", capture=CAPTURES),
        expand(RESULTS_DIR / "{capture}" / "mesh", capture=CAPTURES),
        expand(RESULTS_DIR / "{capture}" / "export", capture=CAPTURES),
        [RESULTS_DIR / c / "evaluate" for c in CAPTURES if has_ground_truth(c)],
        expand(RESULTS_DIR / "{capture}" / "report", capture=CAPTURES),


rule decode:
    """Photos (RAW or JPEG/PNG/TIFF) -> linear exposure-normalized EXR, sRGB PNG, clipped masks."""
    input:
        photos=lambda wc: [str(p) for p in find_photos(CAPTURES_DIR / wc.capture)[1]],
        capture_yaml=capture_config,
    params:
        config=config_digest("decode"),
    output:
        directory(RESULTS_DIR / "{capture}" / "decode"),
    log:
        RESULTS_DIR / "{capture}" / "logs" / "decode.log",
    shell:
        "{ORCA} decode {CAPTURES_DIR}/{wildcards.capture} --out {output} --preset {PRESET} {SET} > {log} 2>&1"


rule poses:
    """Decoded photos -> cameras.json in the object-centred unit-sphere frame (pycolmap SfM, or the capture's
    own cameras.json / transforms.json), transforms.json, sparse/, poses_report.json, poses.png."""
    input:
        unpack(poses_inputs),
        decode=RESULTS_DIR / "{capture}" / "decode",
        capture_yaml=capture_config,
    params:
        config=config_digest("poses"),
    output:
        directory(RESULTS_DIR / "{capture}" / "poses"),
    log:
        RESULTS_DIR / "{capture}" / "logs" / "poses.log",
    threads: 4
    shell:
        "{ORCA} poses {CAPTURES_DIR}/{wildcards.capture} --decode {input.decode} --out {output} --preset {PRESET} "
        "--set poses.num_threads={threads} {SET} > {log} 2>&1"


rule masks:
    """Posed photos -> object masks (automatic: unit-sphere prior, support plane, depth sweep, GrabCut and the
    visual hull made to agree; or the user's CAPTURE/masks/ for all or some photos), cameras.json re-normalized
    to the object's tight bounding sphere, overlays, contact sheet, masks_report.json."""
    input:
        unpack(user_masks),
        decode=RESULTS_DIR / "{capture}" / "decode",
        poses=RESULTS_DIR / "{capture}" / "poses",
        capture_yaml=capture_config,
    params:
        config=config_digest("masks"),
    output:
        directory(RESULTS_DIR / "{capture}" / "masks"),
    log:
        RESULTS_DIR / "{capture}" / "logs" / "masks.log",
    shell:
        "{ORCA} masks {CAPTURES_DIR}/{wildcards.capture} --poses {input.poses} --decode {input.decode} "
        "--out {output} --preset {PRESET} {SET} > {log} 2>&1"


rule train:
    """Decoded photos + cameras + masks -> the trained model (SDF, diffuse head, environment field). The cameras
    are the masks stage's (the poses stage's, re-normalized so that the object's tight sphere is the unit
    sphere), for real and synthetic captures alike: evaluation aligns them to the ground truth. When the poses
    stage resampled the photos to pinhole (poses/undistorted/), training reads those. Its sparse points
    (poses/sparse/) give the environment field sparse depth of the surroundings (losses.sparse_depth).
    Checkpoints go to train.checkpoints/ beside the output, so a killed job resumes where it stopped."""
    input:
        decode=RESULTS_DIR / "{capture}" / "decode",
        poses=RESULTS_DIR / "{capture}" / "poses",
        masks=RESULTS_DIR / "{capture}" / "masks",
        capture_yaml=capture_config,
    params:
        config=config_digest("train"),
    output:
        directory(RESULTS_DIR / "{capture}" / "train"),
    log:
        RESULTS_DIR / "{capture}" / "logs" / "train.log",
    threads: workflow.cores
    shell:
        "images={input.decode}; if [ -d {input.poses}/undistorted ]; then images={input.poses}/undistorted; fi; "
        "points=; if [ -d {input.poses}/sparse ]; then points='--points {input.poses}/sparse'; fi; "
        "{ORCA} train --decode $images --cameras {input.masks}/cameras.json --masks {input.masks}/masks $points "
        "--capture {CAPTURES_DIR}/{wildcards.capture} --out {output} --preset {PRESET} {SET} > {log} 2>&1"


rule mesh:
    """The trained SDF -> mesh.ply (open3d marching cubes, diffuse-head vertex colours; mesh_colmap.ply when the
    cameras record to_colmap), mesh_report.json, mesh.png."""
    input:
        train=RESULTS_DIR / "{capture}" / "train",
        masks=RESULTS_DIR / "{capture}" / "masks",
    params:
        config=config_digest("mesh", reads_capture_yaml=False),
    output:
        directory(RESULTS_DIR / "{capture}" / "mesh"),
    log:
        RESULTS_DIR / "{capture}" / "logs" / "mesh.log",
    shell:
        "{ORCA} mesh {input.train} --cameras {input.masks}/cameras.json --out {output} --preset {PRESET} {SET} > {log} 2>&1"


rule export:
    """The trained model -> environment views + depth (EXR + PNG) from virtual cameras at the object, an
    equirectangular panorama + depth, the environment as a point cloud, orbit and flythrough videos (MP4),
    object renders (combined, diffuse, specular, normals). Rendering uses every core."""
    input:
        train=RESULTS_DIR / "{capture}" / "train",
        masks=RESULTS_DIR / "{capture}" / "masks",
    params:
        config=config_digest("export", reads_capture_yaml=False),
    output:
        directory(RESULTS_DIR / "{capture}" / "export"),
    log:
        RESULTS_DIR / "{capture}" / "logs" / "export.log",
    threads: workflow.cores
    shell:
        "{ORCA} export {input.train} --cameras {input.masks}/cameras.json --out {output} --preset {PRESET} {SET} > {log} 2>&1"


rule evaluate:
    """A synthetic capture's trained model against its ground truth: camera alignment and pose errors, the
    mesh's Chamfer distance, normals, diffuse / specular / combined, environment views and their depth (8
    object views at half size keep it minutes on a CPU)."""
    input:
        train=RESULTS_DIR / "{capture}" / "train",
        masks=RESULTS_DIR / "{capture}" / "masks",
        mesh=RESULTS_DIR / "{capture}" / "mesh",
        ground_truth=CAPTURES_DIR / "{capture}" / "ground_truth",
    output:
        directory(RESULTS_DIR / "{capture}" / "evaluate"),
    log:
        RESULTS_DIR / "{capture}" / "logs" / "evaluate.log",
    shell:
        "{ORCA} evaluate {input.train} --ground-truth {input.ground_truth} --cameras {input.masks}/cameras.json "
        "--mesh {input.mesh}/mesh.ply --out {output} --views 8 --downscale 2 > {log} 2>&1"


rule report:
    """Every stage's folder -> report/report.html: one self-contained page (pictures embedded, no network) with
    each stage's figures and pictures, training curves, the environment panorama, and the evaluation when there
    is one. Cheap: seconds."""
    input:
        unpack(report_inputs),
    output:
        directory(RESULTS_DIR / "{capture}" / "report"),
    log:
        RESULTS_DIR / "{capture}" / "logs" / "report.log",
    shell:
        "{ORCA} report {RESULTS_DIR}/{wildcards.capture} --out {output} > {log} 2>&1"
