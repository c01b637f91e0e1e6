"""``orca synth`` DNGs through the decode stage: one white balance and exposure normalization bring every view
back to the ground-truth linear render (times scene.json's factor), measured as PSNR."""

from __future__ import annotations

from pathlib import Path

import pytest

from pipeline.artifacts import read_json
from pipeline.config import DecodeConfig
from pipeline.imageio import read_exr
from pipeline.metrics import psnr
from pipeline.results import load_decode
from pipeline.stages.decode import run_decode

pytest.importorskip("mitsuba")

# The demo's resolution (demosaicing error depends on texture scale per pixel); few samples per pixel are
# enough because the photos and the ground truth come from the same render.
OPTIONS = dict(views=3, width=320, height=240, spp=8, env_size=8, coverage_spp=4, seed=2)


@pytest.fixture(scope="module")
def decoded_synth(tmp_path_factory) -> tuple[Path, Path]:
    from pipeline.synth import SCENES, SynthOptions, render_capture

    spec = SCENES["sphere"]
    capture = render_capture(spec, tmp_path_factory.mktemp("synth_decode") / "sphere", SynthOptions(**OPTIONS))
    out = capture.parent / "decode"
    run_decode(capture, out, DecodeConfig(min_images=2))
    return capture, out


def psnr_per_view(capture: Path, decode_dir: Path) -> dict[str, float]:
    factor = read_json(capture / "ground_truth" / "scene.json")["radiance_to_decoded"]["factor"]
    dec = load_decode(decode_dir)
    out = {}
    for name in dec.names:
        truth = read_exr(capture / "ground_truth" / "linear" / f"{name}.exr")[..., :3] * factor
        got = dec.linear(name)
        ok = ~dec.clipped(name) & (truth.max(-1) < 1.0)  # clipped highlights carry no radiance to compare
        out[name] = psnr(got, truth, ok)  # peak 1 = the white level
    return out


def test_synthetic_dngs_decode_back_to_ground_truth(decoded_synth):
    capture, decode_dir = decoded_synth
    scene = read_json(capture / "ground_truth" / "scene.json")
    assert len({p["exposure"]["value"] for p in scene["photos"]}) > 1, "views shot at different EXIF exposures"
    psnr = psnr_per_view(capture, decode_dir)
    print("orca synth DNG -> orca decode vs ground truth, PSNR per view (dB):",
          {k: round(v, 1) for k, v in psnr.items()})
    assert min(psnr.values()) > 32.0
