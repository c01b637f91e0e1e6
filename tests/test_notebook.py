"""``notebooks/inspect.ipynb`` runs from top to bottom on the tiny capture's results, as Jupyter runs it (a kernel
started in the notebook's folder, the parameters set in a cell after the one tagged ``parameters``, papermill's
way), drawing every stage's figures; on partial results it skips what has not run; it is committed without
outputs."""

from __future__ import annotations

import shutil
from pathlib import Path

import nbformat
from helpers import ROOT
from nbclient import NotebookClient

from pipeline.stages.report import run_report

NOTEBOOK = ROOT / "notebooks" / "inspect.ipynb"
KERNEL_TIMEOUT_S = 300  # per cell; the tiny results take seconds


def _executed(results: Path, **parameters) -> nbformat.NotebookNode:
    """The notebook run with ``RESULTS = results`` and ``parameters`` (names of its parameters cell)."""
    nb = nbformat.read(NOTEBOOK, as_version=4)
    index = next(i for i, c in enumerate(nb.cells) if "parameters" in c.metadata.get("tags", []))
    values = {"RESULTS": str(results), **parameters}
    injected = nbformat.v4.new_code_cell("\n".join(f"{k} = {v!r}" for k, v in values.items()),
                                         metadata={"tags": ["injected-parameters"]})
    nb.cells.insert(index + 1, injected)
    NotebookClient(nb, timeout=KERNEL_TIMEOUT_S, kernel_name="python3",
                   resources={"metadata": {"path": str(NOTEBOOK.parent)}}).execute()
    return nb


def _sections(nb: nbformat.NotebookNode) -> dict[str, dict[str, list]]:
    """Per ``## heading`` (and the top, ``""``): the pictures (PNG outputs) and the text its code cells printed or
    displayed."""
    sections: dict[str, dict[str, list]] = {"": {"png": [], "text": []}}
    heading = ""
    for cell in nb.cells:
        if cell.cell_type == "markdown" and cell.source.startswith("## "):
            heading = cell.source.splitlines()[0][3:]
            sections[heading] = {"png": [], "text": []}
        for out in cell.get("outputs", []):
            data = out.get("data", {})
            if "image/png" in data:
                sections[heading]["png"].append(data["image/png"])
            sections[heading]["text"].append(out.get("text", "") + data.get("text/markdown", ""))
    return {h: {"png": s["png"], "text": "\n".join(s["text"])} for h, s in sections.items()}


def test_the_committed_notebook_has_no_outputs_and_one_parameters_cell():
    nb = nbformat.read(NOTEBOOK, as_version=4)
    nbformat.validate(nb)
    code = [c for c in nb.cells if c.cell_type == "code"]
    assert all(c.outputs == [] and c.execution_count is None for c in code), "strip the outputs before committing"
    parameters = [c for c in code if "parameters" in c.metadata.get("tags", [])]
    assert len(parameters) == 1 and parameters[0].source.startswith('RESULTS = "results/demo"')


def test_the_notebook_draws_every_stage_of_the_tiny_results(tiny_results, tmp_path):
    results = tmp_path / "tiny"
    shutil.copytree(tiny_results, results)
    run_report(results)
    sections = _sections(_executed(results, DEVICE="cpu", RENDER_DOWNSCALE=1))
    figures = {h: len(s["png"]) for h, s in sections.items()}
    assert figures == {
        "": 0,
        "Decode: linear photos and clipped highlights": 1,
        "Poses: cameras and sparse points in 3D": 1,
        "Masks over the photos": 1,
        "Training curves": 2,  # the curves, the last preview
        "The model at a chosen camera, beside the photo": 1,
        "The mesh": 2,  # the decimated mesh in 3D, mesh.png
        "The environment from inside the object": 2,  # the views, the panorama
        "Evaluation": 2,  # the object and environment grids
        "The report": 0,
    }
    text = {h: s["text"] for h, s in sections.items()}
    assert all(f"{stage} ✓" in text[""] for stage in ("decode", "train", "evaluate", "report"))
    assert "4 photos at 48 x 36; looking at IMG_0001" in text["Decode: linear photos and clipped highlights"]
    assert "4 of 4 photos have a camera" in text["Poses: cameras and sparse points in 3D"]
    assert "no sparse points (known cameras, no model)" in text["Poses: cameras and sparse points in 3D"]
    assert "iterations in" in text["Training curves"]
    assert "| normal MAE |" in text["Evaluation"]
    assert str((results / "report" / "report.html").resolve()) in text["The report"]


def test_on_partial_results_the_notebook_says_what_to_run(tiny_capture, tiny_results, tmp_path):
    """Decode, and poses from a COLMAP model with 3D points (drawn with the cameras); nothing after them."""
    from helpers import colmap_model

    from pipeline.cameras import load_cameras
    from pipeline.config import PosesConfig
    from pipeline.stages.poses import run_poses

    capture = tmp_path / "capture"
    shutil.copytree(tiny_capture, capture)
    colmap_model(load_cameras(capture / "ground_truth" / "cameras.json"), capture / "sparse" / "0", points=20)
    results = tmp_path / "tiny"
    shutil.copytree(tiny_results / "decode", results / "decode")
    run_poses(capture, results / "decode", results / "poses", PosesConfig())
    sections = _sections(_executed(results, DEVICE="cpu"))
    assert len(sections["Decode: linear photos and clipped highlights"]["png"]) == 1
    poses = sections["Poses: cameras and sparse points in 3D"]
    assert len(poses["png"]) == 1 and "20 sparse points" in poses["text"]
    for heading, stage in (("Masks over the photos", "masks"), ("Training curves", "train"), ("The mesh", "mesh"),
                           ("The environment from inside the object", "export")):
        assert sections[heading]["png"] == [], heading
        assert f"the {stage} stage has not run" in sections[heading]["text"] and f"orca {stage}" in \
            sections[heading]["text"], heading
    assert "No evaluation" in sections["Evaluation"]["text"]
    assert "no report yet" in sections["The report"]["text"]
