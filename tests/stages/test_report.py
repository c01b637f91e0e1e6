"""The report stage on real stage outputs: the tiny synthetic capture run through decode, poses (its known
cameras), masks (its own masks), a few training steps, mesh, export and evaluate by the `orca` CLI, then
`orca report` on the whole results folder, on a partial one, and on folders that are not results."""

from __future__ import annotations

import json
import shutil
from html.parser import HTMLParser
from pathlib import Path

import pytest
from helpers import png_data_uri_image

from pipeline.cli import main
from pipeline.errors import InputError
from pipeline.layout import STAGES
from pipeline.report.page import text
from pipeline.stages.report import run_report


@pytest.fixture(scope="module")
def results(tiny_results) -> Path:
    """``results/tiny/`` with every stage's folder, made by the stages themselves (conftest.py)."""
    return tiny_results


class Page(HTMLParser):
    """The parsed page: section ids, image sources, link targets, every tag, the visible text."""

    def __init__(self, document: str):
        super().__init__(convert_charrefs=True)
        self.sections: list[str] = []
        self.images: list[str] = []
        self.links: list[str] = []
        self.tags: set[str] = set()
        self.text: list[str] = []
        self.open: list[str] = []
        self.feed(document)
        self.close()

    def handle_starttag(self, tag, attrs):
        a = dict(attrs)
        self.tags.add(tag)
        if tag == "section":
            self.sections.append(a.get("id"))
        if tag == "img":
            self.images.append(a.get("src", ""))
        if tag == "a" and not a.get("href", "").startswith("#"):
            self.links.append(a.get("href", ""))
        if tag not in ("img", "meta", "br"):
            self.open.append(tag)

    def handle_endtag(self, tag):
        assert self.open and self.open[-1] == tag, f"</{tag}> closes <{self.open[-1] if self.open else None}>"
        self.open.pop()

    def handle_data(self, data):
        self.text.append(data)

    @property
    def body(self) -> str:
        return " ".join(" ".join(self.text).split())


def _section(document: str, stage: str) -> str:
    start = document.index(f'<section id="{stage}">')
    return document[start : document.index("</section>", start)]


def test_the_report_of_a_whole_results_folder(results, tmp_path):
    out = tmp_path / "report"
    assert main(["report", str(results), "--out", str(out)]) == 0
    document = (out / "report.html").read_text(encoding="utf-8")
    page = Page(document)
    assert page.open == [], "every element is closed"
    assert page.sections == list(STAGES)
    # self-contained: every picture embedded as a PNG, no script, no stylesheet or anything else fetched
    assert len(page.images) >= 30
    for src in page.images:
        png_data_uri_image(src)
    assert "script" not in page.tags and "link" not in page.tags and "iframe" not in page.tags
    assert "http://" not in document and "https://" not in document
    # videos and the point cloud are linked relative to the page, and the links lead to the files
    targets = {(out / href).resolve() for href in page.links}
    for path in ("export/videos/orbit.mp4", "export/videos/flythrough.mp4", "export/environment_points.ply",
                 "mesh/mesh.ply"):
        assert (results / path).resolve() in targets, path
    assert all(t.exists() for t in targets)

    decode = json.loads((results / "decode" / "decode.json").read_text())
    poses = json.loads((results / "poses" / "poses_report.json").read_text())
    masks = json.loads((results / "masks" / "masks_report.json").read_text())
    train = json.loads((results / "train" / "train_report.json").read_text())
    mesh = json.loads((results / "mesh" / "mesh_report.json").read_text())
    export = json.loads((results / "export" / "export.json").read_text())
    evaluation = json.loads((results / "evaluate" / "evaluate.json").read_text())
    section = {s: Page(_section(document, s)).body for s in STAGES}
    assert f"photos decoded {len(decode['images'])}" in section["decode"]
    assert f"{decode['size'][0]} x {decode['size'][1]}" in section["decode"]
    clipped = max(im["clipped_fraction"] for im in decode["images"])
    assert f"{100 * clipped:.2f} %" in section["decode"]
    assert f"registered / total {poses['registered']} / {poses['total']}" in section["poses"]
    assert f"{text(masks['agreement']['median'], 3)} / {text(masks['agreement']['mean'], 3)}" in section["masks"]
    for view in masks["views"]:
        assert view["name"] in section["masks"]
    for warning in masks["warnings"]:  # the tiny capture's 4-view hull is loose: its views are flagged
        assert " ".join(warning.split()) in section["masks"]
    assert f"iterations {train['iterations']}" in section["train"]
    for term, value in train["final_losses"].items():
        assert f"{term} {text(value)}" in section["train"]
    assert "Training curves" in section["train"] and "Preview" in section["train"]
    assert f"vertices {mesh['vertices']}" in section["mesh"] and f"triangles {mesh['triangles']}" in section["mesh"]
    assert f"watertight {'yes' if mesh['watertight'] else 'no'}" in section["mesh"]
    assert f"{export['point_cloud']['points']} points" in section["export"]
    for name in export["environment_views"]:
        assert name in section["export"]
    assert len(Page(_section(document, "export")).images) >= 2 + 2 * len(export["environment_views"]) + 4
    object_means = evaluation["object"]["mean"]
    assert f"normal MAE {text(object_means['normal_mae_deg'])} deg" in section["evaluate"]
    assert f"PSNR specular (sRGB) {text(object_means['psnr_srgb_specular'])} dB" in section["evaluate"]
    assert f"depth AbsRel {text(evaluation['environment']['mean']['depth_absrel'])}" in section["evaluate"]
    assert f"Chamfer (object radii) {text(evaluation['mesh']['chamfer_fraction'])}" in section["evaluate"]
    assert len(Page(_section(document, "evaluate")).images) == 2, "object and environment grids"

    manifest = json.loads((out / "manifest.json").read_text())
    assert manifest["stage"] == "report" and manifest["problems"] == []
    assert manifest["sections"] == dict.fromkeys(STAGES, "present")
    assert {"evaluate/evaluate.json", "train/metrics.jsonl", "export/export.json"} <= set(manifest["inputs"])


def test_partial_results_say_what_is_missing_and_escape_text(results, tmp_path):
    partial = tmp_path / "tiny"
    for stage in ("decode", "masks", "mesh"):
        shutil.copytree(results / stage, partial / stage)
    (partial / "mesh" / "mesh_report.json").unlink()  # a stage folder that lacks its report
    report = json.loads((partial / "masks" / "masks_report.json").read_text())
    report["warnings"] = ['view <b>IMG_0001</b> & "friends" <script>alert(1)</script>']
    (partial / "masks" / "masks_report.json").write_text(json.dumps(report))

    summary = run_report(partial)
    document = (partial / "report" / "report.html").read_text(encoding="utf-8")
    page = Page(document)
    assert page.sections == list(STAGES) and page.open == []
    assert summary["sections"] == {"decode": "present", "poses": "missing", "masks": "present", "train": "missing",
                                   "mesh": "incomplete", "export": "missing", "evaluate": "missing"}
    for stage in ("poses", "train", "export"):
        assert "This stage has not run" in _section(document, stage) and f"orca {stage}" in _section(document, stage)
    assert "No evaluation" in _section(document, "evaluate")
    assert "mesh/mesh_report.json is missing" in page.body
    assert len(Page(_section(document, "mesh")).images) == 1, "mesh.png is still shown"
    # text from the files is escaped, never markup
    assert "script" not in page.tags and "<b>" not in document
    assert "&lt;script&gt;alert(1)&lt;/script&gt;" in document and "&amp; &quot;friends&quot;" in document
    assert 'view <b>IMG_0001</b> & "friends" <script>alert(1)</script>' in page.body


def test_every_section_says_which_file_is_damaged(results, tmp_path):
    """Each stage's own file missing or damaged: every section still renders, names the file, and shows the
    rest of what the stage wrote."""
    damaged = tmp_path / "tiny"
    shutil.copytree(results, damaged, ignore=shutil.ignore_patterns("report"))
    (damaged / "decode" / "decode.json").write_text("{not json")
    (damaged / "decode" / "manifest.json").unlink()
    (damaged / "poses" / "poses_report.json").unlink()
    (damaged / "masks" / "masks_report.json").write_text("[1, 2")
    (damaged / "train" / "train_report.json").unlink()
    (damaged / "train" / "metrics.jsonl").write_text("\n")
    (damaged / "mesh" / "mesh_report.json").unlink()
    (damaged / "mesh" / "mesh.png").write_bytes(b"not a picture")
    (damaged / "export" / "export.json").unlink()
    (damaged / "export" / "panorama" / "panorama_depth.png").unlink()
    (damaged / "evaluate" / "evaluate.json").write_text("")

    summary = run_report(damaged)
    document = (damaged / "report" / "report.html").read_text(encoding="utf-8")
    page = Page(document)
    assert page.sections == list(STAGES) and page.open == []
    assert summary["sections"] == dict.fromkeys(STAGES, "incomplete")
    files = {"decode": "decode.json", "poses": "poses_report.json", "masks": "masks_report.json",
             "train": "train_report.json", "mesh": "mesh_report.json", "export": "export.json",
             "evaluate": "evaluate.json"}
    for stage, name in files.items():
        section = Page(_section(document, stage)).body
        assert f"{damaged / stage / name} is missing or unreadable." in section, stage
        assert f"{stage}/{name}" in " ".join(summary["problems"]), stage
    section = {s: Page(_section(document, s)) for s in STAGES}
    assert "decode/manifest.json is missing: the folder may be incomplete." in section["decode"].body
    assert "mesh/mesh.png could not be read" in section["mesh"].body and "Mesh: mesh.ply" in section["mesh"].body
    assert "metrics.jsonl has no rows." in section["train"].body and "Preview" in section["train"].body
    assert len(section["poses"].images) == 1 and len(section["masks"].images) == 1, "poses.png, the contact sheet"
    assert "export/panorama/panorama_depth.png is missing." in section["export"].body
    assert len(section["export"].images) >= 1 + 2 * len(json.loads(
        (results / "export" / "export.json").read_text())["environment_views"]), "the views found by their files"


def test_a_section_that_cannot_be_built_and_poses_from_sfm(results, tmp_path):
    """A report whose content is of the wrong kind stops only its own section; poses from SfM show their
    figures, warnings and per-photo errors; a damaged metrics log is counted."""
    odd = tmp_path / "tiny"
    shutil.copytree(results, odd, ignore=shutil.ignore_patterns("report"))
    masks = json.loads((odd / "masks" / "masks_report.json").read_text())
    (odd / "masks" / "masks_report.json").write_text(json.dumps({**masks, "views": 5}))
    poses = json.loads((odd / "poses" / "poses_report.json").read_text())
    poses.update(source="sfm", features={"min": 10, "median": 20, "max": 30, "per_image": {"IMG_0001": 10}},
                 mean_reprojection_error_px=0.73, models=[3, 1], not_registered=["IMG_0004"], pairs_matched=6,
                 not_registered_why={"IMG_0004": "in a separate model of 1 photos"},
                 pairs_verified=5, reprojection_error_px_per_image={"IMG_0001": 0.5, "IMG_0002": 1.25})
    (odd / "poses" / "poses_report.json").write_text(json.dumps(poses))
    with (odd / "train" / "metrics.jsonl").open("a") as f:
        f.write('{"step": 9, "lo\n')

    summary = run_report(odd)
    document = (odd / "report" / "report.html").read_text(encoding="utf-8")
    page = Page(document)
    assert page.sections == list(STAGES) and page.open == []
    assert summary["sections"] == {**dict.fromkeys(STAGES, "present"), "masks": "incomplete", "train": "incomplete"}
    assert summary["summaries"]["masks"] == "could not be read"
    masks_section = Page(_section(document, "masks")).body
    assert "This section could not be built: TypeError" in masks_section and "Folder" in masks_section
    poses_section = Page(_section(document, "poses")).body
    assert "cameras from SfM (pycolmap)" in poses_section and "image pairs matched / verified 6 / 5" in poses_section
    assert "SfM split the photos into 2 models [3, 1]" in poses_section
    assert "1 photo(s) without a camera: IMG_0004" in poses_section
    assert "why not registered IMG_0004: in a separate model of 1 photos" in poses_section
    assert "reprojection error per photo (2)" in poses_section and "IMG_0002 1.25" in poses_section
    assert summary["summaries"]["poses"] == "4/4 registered, reprojection 0.73 px"
    assert "1 line(s) of metrics.jsonl did not parse." in Page(_section(document, "train")).body
    assert "train/metrics.jsonl: 1 line(s) did not parse" in summary["problems"]
    assert len(Page(_section(document, "export")).images) >= 2, "the other sections are whole"


def test_not_a_results_folder(tmp_path, tiny_capture):
    with pytest.raises(InputError, match="results folder not found") as e:
        run_report(tmp_path / "nowhere")
    assert str(tmp_path / "nowhere") in str(e.value)
    with pytest.raises(InputError, match="not a results folder: none of decode/") as e:
        run_report(tiny_capture)  # a capture folder, not its results
    assert str(tiny_capture) in str(e.value)
    (tmp_path / "a_file").write_text("x")
    with pytest.raises(InputError, match="a file, not a folder"):
        run_report(tmp_path / "a_file")
    assert main(["report", str(tmp_path / "nowhere")]) == 2
    assert not (tmp_path / "nowhere").exists(), "nothing written"
