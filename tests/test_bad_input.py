"""Bad inputs and faults against every stage: each test holds one defect of the "nothing lost, nothing
crashes" list fixed (data loss, signals, bad input accepted, tracebacks, misleading messages). Inputs are made
in the test and small: seconds each, but for the few marked slow.
"""

from __future__ import annotations

from pathlib import Path

import pytest

# A few steps of a very small model: what is tested is the bookkeeping, not the quality.
TINY_TRAIN = [
    "train.iterations=6", "train.batch_rays=64", "train.mask_warmup=2", "train.checkpoint_every=2",
    "train.preview_every=6", "train.preview_downscale=4", "train.log_every=1", "train.n_coarse=8",
    "train.n_fine=4", "train.env_samples=6", "train.grid_levels=4", "train.grid_log2_table=10",
    "train.env_grid_log2_table=10", "train.sdf_hidden=16", "train.env_hidden=16", "train.device=cpu",
]

# ---------------------------------------------------------------- data loss: --out, superseded checkpoints


def _orca(*args) -> int:
    """``orca ARGS`` in this process: its exit status; its log reaches pytest's caplog (not the terminal's)."""
    from unittest import mock

    from pipeline import cli

    with mock.patch.object(cli, "setup_logging", lambda verbose=False: None):
        return cli.main([str(a) for a in args])


def _capture_copy(tiny_capture, folder):
    """The tiny capture's photos (and ground truth) in a folder of the test's own."""
    import shutil

    return Path(shutil.copytree(tiny_capture, folder))


def _tree(folder) -> dict[str, bytes]:
    return {str(p.relative_to(folder)): p.read_bytes() for p in sorted(Path(folder).rglob("*")) if p.is_file()}


@pytest.mark.parametrize("where", ["capture", "parent"])
def test_decode_never_replaces_its_capture(tiny_capture, tmp_path, where):
    """Item 1: `orca decode caps/s --out caps/s` (or --out the capture's parent) deleted the photos."""
    capture = _capture_copy(tiny_capture, tmp_path / "caps" / "s")
    before = _tree(tmp_path / "caps")
    out = capture if where == "capture" else capture.parent
    assert _orca("decode", capture, "--out", out) == 2
    assert _tree(tmp_path / "caps") == before


def test_a_stage_replaces_only_a_folder_it_wrote(tiny_capture, tiny_decode, tmp_path, caplog):
    """Item 1: --out of another stage's folder, of a user's folder, of a file: refused with the folder named;
    a folder the same stage wrote is replaced, an empty one is used."""
    from tiny_model import orbit_cameras, write_untrained_train_dir

    from pipeline.cameras import save_cameras

    gt = tiny_capture / "ground_truth"
    decode_before = _tree(tiny_decode)
    assert _orca("train", "--decode", tiny_decode, "--ground-truth", gt, "--out", tiny_decode) == 2
    assert _tree(tiny_decode) == decode_before
    results = tmp_path / "results"
    assert _orca("decode", tiny_capture, "--out", results / "decode") == 0
    assert _orca("train", "--decode", results / "decode", "--ground-truth", gt, "--out", results / "decode") == 2
    assert "the output folder is the train stage's input" in caplog.text

    train = write_untrained_train_dir(tmp_path / "train")
    cameras = tmp_path / "cams.json"
    save_cameras(cameras, orbit_cameras(1, 8, 6))
    user = tmp_path / "user"
    user.mkdir()
    (user / "thesis.txt").write_text("years of work")
    a_file = tmp_path / "notes.txt"
    a_file.write_text("notes")
    caplog.clear()
    assert _orca("render", train, "--cameras", cameras, "--out", user) == 2
    assert "did not write" in caplog.text and str(user) in caplog.text
    assert _orca("render", train, "--cameras", cameras, "--out", a_file) == 2
    assert _orca("render", train, "--cameras", cameras, "--out", a_file / "views") == 2
    assert (user / "thesis.txt").read_text() == "years of work" and a_file.read_text() == "notes"
    assert _orca("render", train, "--cameras", cameras, "--out", results / "decode") == 2, "another stage's folder"
    assert (results / "decode" / "decode.json").is_file()

    (tmp_path / "empty").mkdir()
    assert _orca("render", train, "--cameras", cameras, "--out", tmp_path / "empty") == 0
    (tmp_path / "empty" / "old.txt").write_text("an earlier render's leftover")  # its own folder: replaced
    assert _orca("render", train, "--cameras", cameras, "--out", tmp_path / "empty") == 0
    assert not (tmp_path / "empty" / "old.txt").exists()


def test_every_superseded_checkpoint_set_is_kept(tiny_capture, tiny_decode, tmp_path):
    """Item 2: a second config change deleted the first set of superseded checkpoints."""
    from pipeline.config import load_config
    from pipeline.stages.train import checkpoint_dir_for, run_train

    gt = tiny_capture / "ground_truth"
    out = tmp_path / "train"
    for hidden in (16, 24, 32):
        cfg = load_config(preset="fast", overrides=[*TINY_TRAIN, f"train.sdf_hidden={hidden}"]).train
        run_train(tiny_decode, gt / "cameras.json", gt / "masks", out, cfg, max_steps=1)
    kept = sorted((tmp_path / "train.checkpoints.superseded").iterdir())
    assert len(kept) == 2 and all(list(k.glob("step_*.pt")) for k in kept)
    assert list(checkpoint_dir_for(out).glob("step_*.pt"))


def test_shorter_iterations_go_on_from_an_earlier_checkpoint(tiny_capture, tiny_decode, tmp_path, caplog):
    """Item 9: train.iterations below the newest checkpoint's step wrote the longer model ("step 30 of 20")."""
    from pipeline.config import load_config
    from pipeline.errors import InputError
    from pipeline.stages.train import checkpoint_dir_for, load_checkpoint, run_train

    gt = tiny_capture / "ground_truth"
    out = tmp_path / "train"

    def train(iterations, **kw):
        cfg = load_config(preset="fast", overrides=[*TINY_TRAIN, f"train.iterations={iterations}",
                                                    "train.checkpoint_every=2"]).train
        return run_train(tiny_decode, gt / "cameras.json", gt / "masks", out, cfg, **kw)

    assert train(6, max_steps=4) is None  # checkpoints at steps 2 and 4
    result = train(3)
    assert result is not None and result.iterations == 3
    assert load_checkpoint(out / "model.pt")["step"] == 3
    assert "going on from step_0000002.pt" in caplog.text
    assert (checkpoint_dir_for(out) / "step_0000004.pt").is_file(), "the newer checkpoint is kept"
    for step in (2, 3):
        (checkpoint_dir_for(out) / f"step_{step:07d}.pt").unlink()
    with pytest.raises(InputError, match="past train.iterations=3"):
        train(3)


def test_restart_deletes_only_a_checkpoint_folder(tiny_capture, tiny_decode, tmp_path):
    """--restart deleted the checkpoint folder whole, whatever else a user had put in it."""
    from pipeline.config import load_config
    from pipeline.errors import InputError
    from pipeline.stages.train import checkpoint_dir_for, run_train

    gt = tiny_capture / "ground_truth"
    out = tmp_path / "train"
    cfg = load_config(preset="fast", overrides=TINY_TRAIN).train
    run_train(tiny_decode, gt / "cameras.json", gt / "masks", out, cfg, max_steps=1)
    (checkpoint_dir_for(out) / "my_notes.txt").write_text("keep me")
    with pytest.raises(InputError, match="my_notes.txt"):
        run_train(tiny_decode, gt / "cameras.json", gt / "masks", out, cfg, restart=True, max_steps=1)
    assert (checkpoint_dir_for(out) / "my_notes.txt").is_file()



def test_a_stage_removes_the_temporary_folders_killed_runs_left(tiny_capture, tmp_path):
    """Item 4: `.<stage>.*.partial` folders left by SIGKILL were never cleaned. Those of a live writer stay."""
    import os
    import socket

    results = tmp_path / "results"
    results.mkdir()
    host = socket.gethostname().split(".")[0].replace("-", "_")
    dead = results / f".decode.{host}-{2**22 + 12345}.x1y2.partial"  # above any pid_max: no such process
    legacy = results / ".decode.ab12cd34.partial"  # the naming of earlier versions (no writer recorded)
    live = results / f".decode.{host}-{os.getpid()}.q9.partial"
    other = results / ".masks.zz99.partial"  # another stage's: not decode's to judge
    for folder in (dead, legacy, live, other):
        folder.mkdir()
        (folder / "linear").mkdir()
    assert _orca("decode", tiny_capture, "--out", results / "decode") == 0
    assert not dead.exists() and not legacy.exists()
    assert live.is_dir() and other.is_dir()


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
