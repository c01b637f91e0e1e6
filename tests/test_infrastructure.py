"""Shared infrastructure: image I/O round trips, cameras.json, atomic artifacts, config validation, CLI."""

from __future__ import annotations

import json
import os
import stat
import subprocess
import sys

import numpy as np
import pytest

from pipeline.artifacts import atomic_dir, read_json, write_json, write_manifest
from pipeline.cameras import Camera, CameraSet, intrinsics_from_fov, load_cameras, look_at, save_cameras
from pipeline.config import PRESETS, load_config
from pipeline.errors import ConfigError, InputError
from pipeline.imageio import linear_to_srgb, read_exr, read_image, srgb_to_linear, write_exr, write_png

# --- image I/O ----------------------------------------------------------------------------------------


@pytest.mark.parametrize("shape", [(6, 9), (6, 9, 3), (6, 9, 4)])
def test_exr_round_trip_is_exact_in_float32(tmp_path, shape):
    rng = np.random.default_rng(0)
    image = (rng.standard_normal(shape) * 100).astype(np.float32)
    image.flat[0] = np.inf  # depth maps use inf for "no hit"
    write_exr(tmp_path / "a.exr", image)
    back = read_exr(tmp_path / "a.exr")
    assert back.shape == shape and back.dtype == np.float32
    np.testing.assert_array_equal(back, image)


def test_exr_half_precision_is_close(tmp_path):
    image = np.linspace(0.01, 10, 60, dtype=np.float32).reshape(4, 5, 3)
    write_exr(tmp_path / "h.exr", image, half=True)
    np.testing.assert_allclose(read_exr(tmp_path / "h.exr"), image, rtol=1e-3)


@pytest.mark.parametrize("dtype", [np.uint8, np.uint16])
def test_png_round_trip_keeps_rgb_order(tmp_path, dtype):
    image = np.zeros((4, 5, 3), dtype=dtype)
    image[..., 0] = np.iinfo(dtype).max  # pure red must stay red (OpenCV is BGR inside)
    write_png(tmp_path / "r.png", image)
    back = read_image(tmp_path / "r.png")
    np.testing.assert_array_equal(back, image)


def test_srgb_transfer_inverts_and_matches_reference_points():
    x = np.linspace(0, 1, 1001, dtype=np.float32)
    np.testing.assert_allclose(srgb_to_linear(linear_to_srgb(x)), x, atol=2e-6)
    # IEC 61966-2-1: 18 % grey encodes to ~0.4614, the linear segment ends at 0.0031308 -> 0.04045
    np.testing.assert_allclose(linear_to_srgb(np.float32(0.18)), 0.46135, atol=1e-4)
    np.testing.assert_allclose(linear_to_srgb(np.float32(0.0031308)), 0.04045, atol=1e-5)


# --- cameras.json -------------------------------------------------------------------------------------


def _camera(name="c0", eye=(3.0, 0.0, 1.0)) -> Camera:
    fx, fy, cx, cy = intrinsics_from_fov(64, 48, 60)
    return Camera(name=name, image=f"{name}.dng", width=64, height=48, fx=fx, fy=fy, cx=cx, cy=cy,
                  camera_to_world=look_at(np.array(eye), np.zeros(3)).tolist())


def test_cameras_round_trip_and_look_at_projects_target_to_centre(tmp_path):
    cams = CameraSet(cameras=[_camera("a"), _camera("b", eye=(0.0, -2.0, 0.5))])
    save_cameras(tmp_path / "cameras.json", cams)
    back = load_cameras(tmp_path / "cameras.json")
    assert back == cams
    for cam in back.cameras:
        w2c = np.linalg.inv(cam.c2w)
        p = w2c[:3, :3] @ np.zeros(3) + w2c[:3, 3]
        assert p[2] > 0, "target must be in front of the camera (OpenCV z forward)"
        uv = (cam.K @ p)[:2] / p[2]
        np.testing.assert_allclose(uv, [cam.cx, cam.cy], atol=1e-9)
        # OpenCV: image y points down, so world up (+z) must map to negative camera y
        assert (w2c[:3, :3] @ np.array([0, 0, 1.0]))[1] < 0


def test_cameras_reject_non_rigid_pose_and_name_the_file(tmp_path):
    bad = _camera().model_dump()
    bad["camera_to_world"][0][:3] = [2.0 * v for v in bad["camera_to_world"][0][:3]]
    path = tmp_path / "cameras.json"
    path.write_text(json.dumps({"cameras": [bad]}))
    with pytest.raises(InputError, match=r"(?s)cameras.json.*(rigid|orthogonal)"):
        load_cameras(path)
    with pytest.raises(InputError, match="not found"):
        load_cameras(tmp_path / "missing.json")


# --- atomic artifacts ---------------------------------------------------------------------------------


def test_atomic_dir_failure_leaves_previous_artifact_untouched(tmp_path):
    out = tmp_path / "decode"
    with atomic_dir(out, "decode") as tmp:
        (tmp / "a.txt").write_text("first")
        write_manifest(tmp, stage="decode")
    with pytest.raises(RuntimeError):
        with atomic_dir(out, "decode") as tmp:
            (tmp / "a.txt").write_text("half")
            raise RuntimeError("interrupted")
    assert (out / "a.txt").read_text() == "first"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["decode"], "no temporary folder left behind"


def test_atomic_dir_replaces_whole_folder(tmp_path):
    out = tmp_path / "stage"
    with atomic_dir(out, "stage") as tmp:
        (tmp / "old.txt").write_text("x")
        write_manifest(tmp, stage="stage")
    with atomic_dir(out, "stage") as tmp:
        (tmp / "new.txt").write_text("y")
    assert sorted(p.name for p in out.iterdir()) == ["new.txt"]


def test_atomic_artifacts_get_the_modes_of_plain_files_and_folders(tmp_path):
    """tempfile's private 0600/0700 must not leak into the artifacts (other users read the results)."""
    old = os.umask(0o022)
    try:
        with atomic_dir(tmp_path / "stage", "stage") as tmp:
            (tmp / "a.txt").write_text("x")
        write_json(tmp_path / "stage" / "b.json", {"k": 1})
    finally:
        os.umask(old)
    assert stat.S_IMODE((tmp_path / "stage").stat().st_mode) == 0o755
    assert stat.S_IMODE((tmp_path / "stage" / "b.json").stat().st_mode) == 0o644


def test_manifest_records_input_hash_and_versions(tmp_path):
    src = tmp_path / "in.bin"
    src.write_bytes(b"abc")
    write_manifest(tmp_path, stage="decode", inputs={"in": src}, config={"k": 1})
    m = read_json(tmp_path / "manifest.json")
    assert m["inputs"]["in"]["sha256"] == "ba7816bf8f01cfea414140de5dae2223b00361a396177a9cb410ff61f20015ad"
    assert m["config"] == {"k": 1} and "numpy" in m["versions"]
    write_json(tmp_path / "x.json", {"a": np.float32(1.5), "b": np.arange(2)})
    assert read_json(tmp_path / "x.json") == {"a": 1.5, "b": [0, 1]}


# --- config -------------------------------------------------------------------------------------------


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
            "iterations": 3000, "batch_rays": 512, "mask_warmup": 300, "checkpoint_every": 250,
            "preview_every": 500, "grid_levels": 8, "grid_log2_table": 17, "grid_max_resolution": 128,
            "texture_levels": 8, "texture_log2_table": 17, "texture_max_resolution": 512,
            "env_grid_log2_table": 17, "n_coarse": 24, "n_fine": 8, "upsample_steps": 2, "band_samples": 16,
            "env_samples": 24, "env_fine": 24, "env_fine_render": 96, "background_rays": 768,
            "cone_samples": 1,
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
# --- CLI ----------------------------------------------------------------------------------------------


def test_cli_lists_stages_and_each_has_help_with_examples():
    from pipeline.cli import COMMANDS

    top = subprocess.run([sys.executable, "-m", "pipeline.cli", "--help"], capture_output=True, text=True)
    assert top.returncode == 0
    for name, _ in COMMANDS:
        assert name in top.stdout
        sub = subprocess.run([sys.executable, "-m", "pipeline.cli", name, "--help"], capture_output=True, text=True)
        assert sub.returncode == 0, sub.stderr
        assert "example" in sub.stdout.lower(), f"`orca {name} --help` should show examples"
