"""Whole-image rendering: chunking changes nothing but speed."""

from __future__ import annotations

import math

import torch

from orca.imaging import (
    ENVIRONMENT_CHUNK,
    environment_chunk,
    render_composite_image,
    render_environment_image,
)
from orca.model import ModelSpec, OrcaModel
from orca.render import RenderSpec
from pipeline.cameras import intrinsics_from_fov, look_at


def test_environment_chunks_depend_on_the_device_and_not_the_image():
    """A CPU renders the environment in small chunks, a GPU in large ones; the image is the same either way
    (an image of 48 x 40 rays spans two of the CPU's chunks and is compared with chunks of 37 rays)."""
    assert environment_chunk(torch.device("cpu")) == ENVIRONMENT_CHUNK["cpu"] < 48 * 40
    assert environment_chunk(torch.device("cuda")) == ENVIRONMENT_CHUNK["cuda"] > ENVIRONMENT_CHUNK["cpu"]
    torch.manual_seed(0)
    model = OrcaModel(ModelSpec(render=RenderSpec(env_samples=16, env_fine=8).for_rendering())).eval()
    h, w = 40, 48
    fx, fy, cx, cy = intrinsics_from_fov(w, h, 50.0)
    K = torch.tensor([[fx, 0, cx], [0, fy, cy], [0, 0, 1]], dtype=torch.float32)
    c2w = torch.from_numpy(look_at([3.0 * math.cos(0.3), 3.0 * math.sin(0.3), 1.0], [0.0, 0.0, 0.0])).float()
    env, env_small = render_environment_image(model, K, c2w, h, w), render_environment_image(model, K, c2w, h, w, 37)
    for key in ("rgb", "depth"):
        torch.testing.assert_close(env[key], env_small[key], rtol=1e-5, atol=1e-6)
    assert env["rgb"].shape == (h, w, 3) and torch.isfinite(env["depth"]).all()
    torch.testing.assert_close(render_composite_image(model, K, c2w, h, w),
                               render_composite_image(model, K, c2w, h, w, 37), rtol=1e-5, atol=1e-6)
