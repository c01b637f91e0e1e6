"""The Snakefile on a tiny synthetic capture: decode -> poses (its known cameras) -> masks (its own masks) ->
train -> mesh -> export -> evaluate -> report run for real, a second run does nothing, a forced export reruns
only what follows it, and a capture of bare photos plans the whole DAG (SfM, automatic masks, the report)."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
from pathlib import Path

import pytest
from helpers import TINY_DAG, snakemake_command


def snakemake(workdir: Path, *args: str, env: dict[str, str] | None = None) -> subprocess.CompletedProcess:
    return subprocess.run(snakemake_command(workdir, TINY_DAG, *args), capture_output=True, text=True, timeout=600,
                          check=False, env=None if env is None else {**os.environ, **env})


@pytest.mark.slow(seconds=70)
def test_the_dag_runs_decode_train_evaluate_then_nothing(tiny_capture, tmp_path):
    (tmp_path / "captures").mkdir()
    shutil.copytree(tiny_capture, tmp_path / "captures" / "tiny")
    # 4 views of 48x36 pixels are too few and too small for SfM: the capture brings its cameras (as a turntable
    # would), so the poses rule runs for real on the known-cameras path (SfM runs in tests/stages/test_poses.py).
    shutil.copy(tiny_capture / "ground_truth" / "cameras.json", tmp_path / "captures" / "tiny" / "cameras.json")
    # 48x36 pixels are too few for the automatic masks (their cues need texture around the object): the capture
    # brings masks (here the ground truth's) as a user would, so the masks rule runs its user-mask path for real
    # (the automatic method runs in tests/stages/test_masks.py).
    shutil.copytree(tiny_capture / "ground_truth" / "masks", tmp_path / "captures" / "tiny" / "masks")
    first = snakemake(tmp_path)
    assert first.returncode == 0, first.stderr[-3000:]
    results = tmp_path / "results" / "tiny"
    for stage in ("decode", "poses", "masks", "train", "evaluate"):
        assert (results / stage / "manifest.json").is_file(), stage
    assert (results / "evaluate" / "evaluate.json").is_file()
    for stage, artifact in (("mesh", "mesh.ply"), ("export", "videos/orbit.mp4"), ("export", "panorama")):
        assert (results / stage / "manifest.json").is_file() and (results / stage / artifact).exists(), artifact
    evaluation = json.loads((results / "evaluate" / "evaluate.json").read_text())
    assert "chamfer" in evaluation["mesh"] and evaluation["poses"]["summary"]["rotation_deg_max"] < 1e-6
    masks = json.loads((results / "masks" / "masks_report.json").read_text())
    assert {v["source"] for v in masks["views"]} == {"user"}
    assert (results / "masks" / "masks" / "IMG_0001.png").is_file()
    train_manifest = json.loads((results / "train" / "manifest.json").read_text())
    assert "masks/cameras.json" in json.dumps(train_manifest)  # trained on the masks stage's tight frame
    # the report comes last, from every stage's folder, evaluate's included (the capture has ground truth)
    report = json.loads((results / "report" / "manifest.json").read_text())
    assert report["sections"] == {s: "present" for s in ("decode", "poses", "masks", "train", "mesh", "export",
                                                         "evaluate")}, report["problems"]
    page = (results / "report" / "report.html").read_text(encoding="utf-8")
    assert page.count("<section id=") == 7 and "data:image/png;base64," in page
    again = snakemake(tmp_path)
    assert again.returncode == 0 and "Nothing to be done" in again.stdout + again.stderr
    # a stage rerun makes the report again (and what depends on it), nothing else
    plan = snakemake(tmp_path, "-n", "--forcerun", "export")
    out = plan.stdout + plan.stderr
    assert plan.returncode == 0, out[-3000:]
    assert "rule report:" in out or "localrule report:" in out
    for rule in ("decode", "poses", "masks", "train", "mesh", "evaluate"):
        assert f"rule {rule}:" not in out, rule
    # An upgrade that changes a default the train stage runs with (here the fast preset's learning rate, patched
    # at interpreter start-up as a new version of the package would ship it) changes no file and no command
    # line: the recorded config hash (the rules' params) is what reruns train and what follows it.
    upgrade = tmp_path / "upgrade"
    upgrade.mkdir()
    (upgrade / "sitecustomize.py").write_text(
        "from pipeline.config import PRESETS\nPRESETS['fast']['train']['lr'] = 1e-3\n"
    )
    plan = snakemake(tmp_path, "-n", env={"PYTHONPATH": str(upgrade)})
    out = plan.stdout + plan.stderr
    assert plan.returncode == 0, out[-3000:]
    for rule in ("train", "mesh", "export", "evaluate", "report"):
        assert f"rule {rule}:" in out or f"localrule {rule}:" in out, rule
    for rule in ("decode", "poses", "masks"):
        assert f"rule {rule}:" not in out, rule


def test_a_capture_of_bare_photos_plans_sfm_masks_and_training(tiny_capture, tmp_path):
    capture = tmp_path / "captures" / "tiny"
    capture.mkdir(parents=True)
    for dng in tiny_capture.glob("*.dng"):
        shutil.copy(dng, capture)
    plan = snakemake(tmp_path, "-n")
    out = plan.stdout + plan.stderr
    assert plan.returncode == 0, out[-3000:]
    for rule in ("decode", "poses", "masks", "train", "mesh", "export", "report"):
        assert f"rule {rule}:" in out or f"localrule {rule}:" in out, rule
    assert "evaluate" not in out  # no ground truth: nothing to evaluate against (nor for the report to wait on)
    # with photos held out of training, the held-out photos are what it is evaluated on, and the report waits
    (capture / "capture.yaml").write_text("train:\n  holdout_every: 2\n")
    plan = snakemake(tmp_path, "-n", "-p")
    out = plan.stdout + plan.stderr
    assert plan.returncode == 0, out[-3000:]
    assert "rule evaluate:" in out and "evaluate" in out and "--held-out" in out and "--ground-truth" not in out
