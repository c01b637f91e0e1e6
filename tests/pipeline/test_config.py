"""The configuration (pipeline.config): layers and overrides, validation naming the problem, presets, the flat
train keys of earlier versions, the digest of a stage's values."""

from __future__ import annotations

import pytest

from pipeline.config import PRESETS, load_config
from pipeline.errors import ConfigError


def test_config_layers_and_overrides(tmp_path):
    f = tmp_path / "capture.yaml"
    f.write_text("preset: fast\ndecode:\n  min_images: 5\n")
    cfg = load_config(f, overrides=["decode.downscale=2"])
    assert cfg.preset == "fast" and cfg.decode.min_images == 5 and cfg.decode.downscale == 2
    assert load_config(f, preset="standard").preset == "standard", "explicit preset wins over the file"
    assert set(PRESETS) >= {"fast", "standard", "paper"}


@pytest.mark.parametrize(
    "text, match",
    [
        ("decode:\n  min_imgs: 5\n", "min_imgs"),  # unknown key: a typo must not pass silently
        ("decode:\n  downscale: 0\n", "downscale"),
        ("preset: turbo\n", "unknown preset"),
        ("- a\n- b\n", "mapping"),
        ("train:\n  render:\n    env_near: 5\n    env_far: 2\n", "env_far"),
    ],
)
def test_config_rejects_bad_files_naming_the_problem(tmp_path, text, match):
    f = tmp_path / "bad.yaml"
    f.write_text(text)
    with pytest.raises(ConfigError, match=match):
        load_config(f)


def test_config_error_from_an_override_names_the_override(tmp_path):
    f = tmp_path / "capture.yaml"
    f.write_text("train:\n  render:\n    ior: 1.9\n")
    with pytest.raises(ConfigError, match=r"--set train.losses.clipped_excess=2"):
        load_config(f, overrides=["train.losses.clipped_excess=2"])


def test_stage_cli_overrides_may_omit_the_stage_section():
    import argparse

    from pipeline.config import add_config_arguments, config_from_arguments

    parser = argparse.ArgumentParser()
    add_config_arguments(parser)
    args = parser.parse_args(
        ["--set", "iterations=7", "--set", "losses.background=0.25", "--set", "mesh.resolution=64"])
    cfg = config_from_arguments(args, "train")
    assert cfg.train.iterations == 7 and cfg.train.losses.background == 0.25 and cfg.mesh.resolution == 64


def test_a_stages_config_digest_follows_its_own_values_only(tmp_path, monkeypatch):
    from pipeline.config import stage_config_digest

    base = stage_config_digest("train", "fast")
    assert stage_config_digest("train", "fast", ["iterations=7"]) != base
    assert stage_config_digest("train", "fast", ["train.iterations=7"]) == stage_config_digest(
        "train", "fast", ["iterations=7"]
    ), "a bare key is the stage's own, as on its CLI"
    assert stage_config_digest("train", "fast", ["mesh.resolution=64"]) == base, "another stage's value"
    assert stage_config_digest("train", "standard") != base
    masks = stage_config_digest("masks", "fast")
    assert stage_config_digest("masks", "fast", ["workers=3"]) == masks, "how it runs, not what it makes"
    assert stage_config_digest("masks", "fast", ["rounds=2"]) != masks
    capture_yaml = tmp_path / "capture.yaml"
    assert stage_config_digest("train", "fast", capture_yaml=capture_yaml) == base, "no capture.yaml: defaults"
    capture_yaml.write_text("train:\n  render:\n    ior: 1.9\n")
    assert stage_config_digest("train", "fast", capture_yaml=capture_yaml) != base
    # a default changed by an upgrade (no file, no command line) changes it too
    monkeypatch.setitem(PRESETS["fast"]["train"], "lr", 1e-3)
    assert stage_config_digest("train", "fast") != base


# The presets as they were written before the train section was nested (flat keys, Python dicts).
FLAT_PRESETS = {
    "fast": {
        "poses": {"max_image_size": 1024},
        "train": {
            "iterations": 1000, "batch_rays": 512, "mask_warmup": 100, "checkpoint_every": 250,
            "preview_every": 500, "grid_levels": 8, "grid_log2_table": 17, "grid_max_resolution": 128,
            "texture_levels": 8, "texture_log2_table": 17, "texture_max_resolution": 512,
            "env_grid_log2_table": 17, "n_coarse": 24, "n_fine": 8, "upsample_steps": 2, "band_samples": 16,
            "env_samples": 24, "env_fine": 24, "env_fine_render": 96, "background_rays": 768,
            "cone_samples": 1, "environment_lr": 0.015,
        },
        "mesh": {"resolution": 128},
        "export": {
            "view_size": 48, "panorama_width": 128, "video_frames": 16, "video_width": 64, "video_height": 48,
            "object_views": 4, "object_downscale": 4,
        },
    },
    "standard": {},
    "paper": {
        "train": {
            "sdf_encoding": "frequency", "sdf_hidden": 256, "sdf_layers": 8, "env_encoding": "ipe", "band_samples": 0,
            "texture_levels": 0, "losses": {"smoothness": 0.0},
            "env_hidden": 256, "env_layers": 8, "n_coarse": 64, "n_fine": 128, "env_samples": 64, "env_fine": 128,
            "cone_samples": 4, "cone_method": "bounding_rays", "iterations": 200000, "batch_rays": 1024,
            "background_rays": 0,
        },
    },
}


@pytest.mark.parametrize("preset", sorted(FLAT_PRESETS))
def test_a_preset_file_resolves_to_the_values_of_its_flat_keys(preset, tmp_path):
    """Each preset's YAML file, and its flat keys of earlier versions over the defaults, give one config."""
    import yaml

    assert preset in PRESETS
    flat = tmp_path / "flat.yaml"
    flat.write_text(yaml.safe_dump(FLAT_PRESETS[preset]))
    from_flat = load_config(flat, preset="standard").model_dump(exclude={"preset"})
    assert load_config(preset=preset).model_dump(exclude={"preset"}) == from_flat


def test_flat_train_keys_still_work_each_with_a_warning_naming_its_new_key(tmp_path, caplog):
    from pipeline.config import TrainConfig, stage_config

    f = tmp_path / "capture.yaml"
    f.write_text("train:\n  grid_levels: 4\n  ior: 1.9\n  losses:\n    mask: 0.2\n")
    with caplog.at_level("WARNING", logger="orca.config"):
        cfg = stage_config("train", "fast", None, ["train.sdf_hidden=16", "n_coarse=8"], capture_yaml=f).train
    assert (cfg.sdf.hash_grid.levels, cfg.render.ior, cfg.sdf.hidden, cfg.render.n_coarse) == (4, 1.9, 16, 8)
    assert cfg.sdf.hash_grid.max_resolution == 128 and cfg.losses.mask == 0.2, "the rest of the group is kept"
    warnings = [r.getMessage() for r in caplog.records]
    assert f"{f}: train.grid_levels is deprecated; write train.sdf.hash_grid.levels" in warnings
    assert "--set train.n_coarse=8: train.n_coarse is deprecated; write train.render.n_coarse" in warnings
    assert len(warnings) == 4
    # a later layer's new key wins over an earlier layer's old one; both in one layer is an error
    assert load_config(f, overrides=["train.render.ior=1.4"]).train.render.ior == 1.4
    f.write_text("train:\n  ior: 1.9\n  render:\n    ior: 1.4\n")
    with pytest.raises(ConfigError, match=r"capture.yaml: train.ior and train.render.ior are both given"):
        load_config(f)
    # a model file of an earlier version holds the flat keys: it is read as the same config, silently
    flat = {"sdf_hidden": 16, "env_far": 50.0, "log_every": 3, "losses": {"mask": 0.2}}
    assert TrainConfig.model_validate(flat) == TrainConfig.model_validate(
        {"sdf": {"hidden": 16}, "render": {"env_far": 50.0}, "logging": {"log_every": 3}, "losses": {"mask": 0.2}})


def test_a_misspelled_key_of_a_train_group_names_the_keys_it_may_be(tmp_path):
    with pytest.raises(ConfigError, match=r"--set train.hiden=32: train.hiden: unknown key; did you mean "
                                          r"'train.sdf.hidden' or 'train.environment.hidden'\?"):
        load_config(overrides=["train.hiden=32"])
    with pytest.raises(ConfigError, match=r"train.sdf.hash_grid.level: unknown key; did you mean 'levels'\?"):
        load_config(overrides=["train.sdf.hash_grid.level=3"])


def test_poses_config_is_validated():
    assert load_config(preset="fast").poses.max_image_size == 1024
    with pytest.raises(ConfigError, match="matcher"):
        load_config(overrides=["poses.matcher=vocabulary"])
    with pytest.raises(ConfigError, match="min_registered_fraction"):
        load_config(overrides=["poses.min_registered_fraction=1.5"])
    with pytest.raises(ConfigError, match="unknown_key"):
        load_config(overrides=["poses.unknown_key=1"])
