"""Bad inputs and faults against every stage: each test holds one defect of the "nothing lost, nothing
crashes" list fixed (data loss, signals, bad input accepted, tracebacks, misleading messages). Inputs are made
in the test and small: seconds each, but for the few marked slow.
"""

from __future__ import annotations

# ---------------------------------------------------------------- data loss: --out, superseded checkpoints

# ---------------------------------------------------------------- signals: SIGTERM, stale temporary folders

# ---------------------------------------------------------------- bad input accepted: masks


def _posed_tiny(capture, decode, out, drop: str | None = None):
    """The poses stage on the tiny capture's ground-truth cameras (no SfM); ``drop``: that photo's camera is
    removed afterwards, as when SfM does not register a photo."""
    import shutil

    from pipeline.cameras import load_cameras, save_cameras
    from pipeline.config import PosesConfig
    from pipeline.stages.poses import run_poses

    shutil.copy(capture / "ground_truth" / "cameras.json", capture / "cameras.json")
    try:
        run_poses(capture, decode, out, PosesConfig(use_masks=False))
    finally:
        (capture / "cameras.json").unlink()
    if drop is not None:
        cams = load_cameras(out / "cameras.json")
        save_cameras(out / "cameras.json",
                     cams.model_copy(update={"cameras": [c for c in cams.cameras if c.name != drop]}))
    return out


def _names(capture):
    return sorted(p.stem for p in (capture / "ground_truth" / "masks").glob("*.png"))


def _true_user_masks(capture, folder, blank=(), speck=()):
    """The ground-truth masks as user masks in ``folder``; the views in ``blank`` all black, in ``speck`` one
    white pixel. Returns the photo names."""
    import numpy as np

    from pipeline.imageio import read_image, write_png

    folder.mkdir()
    names = _names(capture)
    for n in names:
        m = read_image(capture / "ground_truth" / "masks" / f"{n}.png") > 127
        if n in blank:
            m[:] = False
        elif n in speck:
            m[:] = False
            m[0, 0] = True
        write_png(folder / f"{n}.png", m.astype(np.uint8) * 255)
    return names


def test_all_black_user_masks_are_refused_naming_them(tiny_capture, tiny_decode, tmp_path):
    import pytest

    from pipeline.config import MasksConfig
    from pipeline.errors import InputError
    from pipeline.stages.masks import run_masks

    poses = _posed_tiny(tiny_capture, tiny_decode, tmp_path / "poses")
    names = _true_user_masks(tiny_capture, tmp_path / "user", blank=_names(tiny_capture))
    with pytest.raises(InputError, match="empty") as err:
        run_masks(tiny_capture, poses, tmp_path / "masks", MasksConfig(), user_masks_dir=tmp_path / "user")
    assert all(f"{n}.png" in str(err.value) for n in names) and "Fix:" in str(err.value)
    with pytest.raises(InputError, match="every user mask is empty"):  # even when empty masks are allowed
        run_masks(tiny_capture, poses, tmp_path / "masks", MasksConfig(user_mask_min_fraction=0),
                  user_masks_dir=tmp_path / "user")
    assert not (tmp_path / "masks").exists()


def test_one_empty_or_nearly_empty_user_mask_is_refused_naming_it(tiny_capture, tiny_decode, tmp_path):
    import pytest

    from pipeline.config import MasksConfig
    from pipeline.errors import InputError
    from pipeline.stages.masks import run_masks

    poses = _posed_tiny(tiny_capture, tiny_decode, tmp_path / "poses")
    first, second, *rest = _names(tiny_capture)
    _true_user_masks(tiny_capture, tmp_path / "user", blank=[first], speck=[second])
    with pytest.raises(InputError, match=r"2 user mask\(s\).*empty") as err:
        run_masks(tiny_capture, poses, tmp_path / "masks", MasksConfig(), user_masks_dir=tmp_path / "user")
    message = str(err.value)
    assert f"{first}.png" in message and f"{second}.png" in message and "user_mask_min_fraction" in message
    assert not any(f"{n}.png" in message for n in rest)


def test_an_object_sphere_not_from_the_hull_says_so_in_the_report(tiny_capture, tiny_decode, tmp_path):
    """An empty mask let through on purpose (the object out of that photo) empties the 4-view hull: the
    report must say the sphere is the poses stage's, not the hull's."""
    from pipeline.config import MasksConfig
    from pipeline.results import load_masks
    from pipeline.stages.masks import run_masks

    poses = _posed_tiny(tiny_capture, tiny_decode, tmp_path / "poses")
    _true_user_masks(tiny_capture, tmp_path / "user", blank=_names(tiny_capture)[:1])
    result = run_masks(tiny_capture, poses, tmp_path / "masks", MasksConfig(user_mask_min_fraction=0),
                       user_masks_dir=tmp_path / "user")
    sphere = load_masks(tmp_path / "masks").report["object_sphere"]
    assert result.sphere_radius == 1.0 and sphere["fallback"] is True
    assert "visual hull" in sphere["from"] and "empty" in sphere["from"] and "poses" in sphere["from"]


def test_train_refuses_masks_of_another_aspect_ratio_like_the_masks_stage(tiny_capture, tiny_decode, tmp_path):
    import numpy as np
    import pytest

    from pipeline.errors import InputError
    from pipeline.imageio import read_image, write_png
    from pipeline.stages.masks import read_user_mask
    from pipeline.stages.train import load_image_set

    truth = tiny_capture / "ground_truth"
    names = _names(tiny_capture)
    doubled, rotated = tmp_path / "doubled", tmp_path / "rotated"
    doubled.mkdir()
    rotated.mkdir()
    for n in names:  # 48x36 photos: masks at 96x72 (the same aspect ratio) and 36x48 (rotated)
        m = read_image(truth / "masks" / f"{n}.png")
        write_png(doubled / f"{n}.png", np.repeat(np.repeat(m, 2, axis=0), 2, axis=1))
        write_png(rotated / f"{n}.png", np.ascontiguousarray(m.T))
    data, _ = load_image_set(tiny_decode, truth / "cameras.json", doubled)
    for n, m in zip(names, data.masks.numpy()):
        np.testing.assert_array_equal(m, read_image(truth / "masks" / f"{n}.png") > 127)
    with pytest.raises(InputError, match="aspect ratio") as by_train:
        load_image_set(tiny_decode, truth / "cameras.json", rotated)
    with pytest.raises(InputError, match="aspect ratio") as by_masks:
        read_user_mask(rotated / f"{names[0]}.png", (48, 36))
    assert f"{names[0]}.png" in str(by_train.value) and "Fix:" in str(by_train.value)
    assert str(by_train.value) == str(by_masks.value)  # one rule, one message


def test_user_masks_of_photos_sfm_dropped_are_skipped(tiny_capture, tiny_decode, tmp_path, caplog):
    import numpy as np
    import pytest

    from pipeline.config import MasksConfig
    from pipeline.errors import InputError
    from pipeline.imageio import write_png
    from pipeline.stages.masks import run_masks

    names = _names(tiny_capture)
    poses = _posed_tiny(tiny_capture, tiny_decode, tmp_path / "poses", drop=names[1])
    _true_user_masks(tiny_capture, tmp_path / "user")
    with caplog.at_level("INFO", logger="orca.masks"):
        result = run_masks(tiny_capture, poses, tmp_path / "masks", MasksConfig(), user_masks_dir=tmp_path / "user")
    assert result.names == result.user == [n for n in names if n != names[1]]
    assert any(names[1] in r.getMessage() and "no camera" in r.getMessage() for r in caplog.records)
    write_png(tmp_path / "user" / "IMG_9999.png", np.zeros((36, 48), np.uint8))  # no such photo: still an error
    with pytest.raises(InputError, match=r"match no photo: IMG_9999\.png"):
        run_masks(tiny_capture, poses, tmp_path / "masks2", MasksConfig(), user_masks_dir=tmp_path / "user")


# ---------------------------------------------------------------- bad input accepted: another capture

# ---------------------------------------------------------------- tracebacks and misleading messages
