"""Shared fixtures: a tiny synthetic capture (rendered once per session) and its decode."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import pytest


@pytest.fixture(scope="session")
def tiny_capture(tmp_path_factory) -> Path:
    """A 4-view 48x36 glossy-sphere capture with ground truth (coarse textures keep it ~10 s)."""
    pytest.importorskip("mitsuba")
    from pipeline.synth import SCENES, SynthOptions, render_capture

    spec = SCENES["sphere"]
    spec = replace(
        spec,
        room=replace(spec.room, texels_per_unit=12.0, prop_texels_per_unit=32.0),
        object=replace(spec.object, albedo=replace(spec.object.albedo, texture_size=(128, 64))),
    )
    options = SynthOptions(views=4, width=48, height=36, spp=16, env_size=16, coverage_spp=9, seed=1)
    return render_capture(spec, tmp_path_factory.mktemp("tiny") / "sphere", options)


@pytest.fixture(scope="session")
def tiny_decode(tiny_capture, tmp_path_factory) -> Path:
    from pipeline.config import DecodeConfig
    from pipeline.stages.decode import run_decode

    out = tmp_path_factory.mktemp("tiny_results") / "decode"
    run_decode(tiny_capture, out, DecodeConfig())
    return out
