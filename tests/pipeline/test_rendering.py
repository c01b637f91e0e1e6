"""Rendering a trained model (pipeline.rendering): the renderer takes the trained config's render settings."""

from __future__ import annotations

from helpers import write_untrained_train_dir

from pipeline.rendering import load_renderer


def test_the_renderer_takes_the_trained_configs_render_settings(tmp_path):
    model = load_renderer(write_untrained_train_dir(tmp_path / "train"), "cpu")
    # train.render.env_fine (colour), env_fine_render (depth) and depth_quantile (helpers.TINY_MODEL)
    assert model.spec.render.deterministic and model.spec.render.env_fine == 0
    assert model.spec.render.for_depth().env_fine == 2
    assert model.spec.render.depth_quantile == 0.4
