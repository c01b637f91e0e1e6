"""Bad inputs and faults against every stage: each test holds one defect of the "nothing lost, nothing
crashes" list fixed (data loss, signals, bad input accepted, tracebacks, misleading messages). Inputs are made
in the test and small: seconds each, but for the few marked slow.
"""

from __future__ import annotations

import logging
from pathlib import Path

import pytest
from helpers import TINY_DAG, TINY_TRAIN, orbit_cameras, snakemake_command, write_untrained_train_dir

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
        cfg = load_config(preset="fast", overrides=[*TINY_TRAIN, f"train.sdf.hidden={hidden}"]).train
        run_train(tiny_decode, gt / "cameras.json", gt / "masks", out, cfg, max_steps=1)
    kept = sorted((tmp_path / "train.checkpoints.superseded").iterdir())
    assert len(kept) == 2 and all(list(k.glob("step_*.pt")) for k in kept)
    assert list(checkpoint_dir_for(out).glob("step_*.pt"))


def test_shorter_iterations_go_on_from_an_earlier_checkpoint(tiny_capture, tiny_decode, tmp_path, caplog):
    """Item 9: train.iterations below the newest checkpoint's step wrote the longer model ("step 30 of 20")."""
    from pipeline.checkpoints import load_checkpoint
    from pipeline.config import load_config
    from pipeline.errors import InputError
    from pipeline.stages.train import checkpoint_dir_for, run_train

    gt = tiny_capture / "ground_truth"
    out = tmp_path / "train"

    def train(iterations, **kw):
        cfg = load_config(preset="fast", overrides=[*TINY_TRAIN, f"train.iterations={iterations}",
                                                    "train.logging.checkpoint_every=2"]).train
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


def test_train_removes_a_checkpoint_cut_short_by_sigkill(tiny_capture, tiny_decode, tmp_path):
    """Item 4, files: a checkpoint being written when SIGKILL came stays as a hidden temporary file."""
    import socket

    from pipeline.config import load_config
    from pipeline.stages.train import checkpoint_dir_for, run_train

    gt = tiny_capture / "ground_truth"
    out = tmp_path / "train"
    cfg = load_config(preset="fast", overrides=TINY_TRAIN).train
    run_train(tiny_decode, gt / "cameras.json", gt / "masks", out, cfg, max_steps=2)
    host = socket.gethostname().split(".")[0].replace("-", "_")
    cut = checkpoint_dir_for(out) / f".step_0000004.pt.{host}-{2**22 + 12345}.k3j9.tmp.pt"
    cut.write_bytes(b"half a checkpoint")
    assert run_train(tiny_decode, gt / "cameras.json", gt / "masks", out, cfg) is not None
    assert not cut.exists()


# ---------------------------------------------------------------- signals: SIGTERM, stale temporary folders

# `orca ARGS` in which the function ``module:name`` (``sys.argv[1:3]``) touches the file ``sys.argv[3]`` and
# waits instead of running: a signal sent once the file is there lands inside the stage, every time.
_HELD_ORCA = """\
import importlib, sys, time
from pathlib import Path

module, name, marker = sys.argv[1:4]


def hold(*args, **kwargs):
    Path(marker).touch()
    time.sleep(600)


setattr(importlib.import_module(module), name, hold)
from pipeline.cli import main

sys.exit(main(sys.argv[4:]))
"""


def _signal_when(proc, ready, what: str, signum: int = 15, group: bool = False, timeout: float = 300) -> str:
    """Send ``signum`` (SIGTERM) to ``proc`` (to its whole process group with ``group``) once ``ready()``; its
    output once it has exited. A test failing on the way kills it (100000 training steps would go on for hours)."""
    import contextlib
    import os
    import signal
    import time

    deadline = time.time() + timeout
    try:
        while not ready():
            assert proc.poll() is None, f"it ended before {what}:\n{proc.communicate()[0][-3000:]}"
            assert time.time() < deadline, f"no {what} after {timeout} s"
            time.sleep(0.1)
        if group:
            os.killpg(proc.pid, signum)
        else:
            proc.send_signal(signum)
        return proc.communicate(timeout=120)[0]
    except BaseException:
        with contextlib.suppress(ProcessLookupError):
            os.killpg(proc.pid, signal.SIGKILL) if group else proc.kill()
        raise


def _stopped_cleanly(output: str, folder: Path, signal_name: str = "SIGTERM") -> None:
    """The log names the signal, no C++ stack dump (pycolmap's glog), no temporary folder left in ``folder``."""
    assert f"stopped by {signal_name}" in output, output[-3000:]
    assert "received by PID" not in output and "*** Aborted" not in output, output[-3000:]
    assert not list(folder.rglob("*.partial")), "a temporary folder was left behind"


@pytest.mark.parametrize(("stage", "signal_name", "status"),
                         [("poses", "SIGTERM", 143), ("masks", "SIGTERM", 143), ("poses", "SIGINT", 130)])
def test_sigterm_stops_a_stage_that_loaded_pycolmap_like_ctrl_c(stage, signal_name, status, tiny_capture,
                                                                 tiny_decode, tmp_path):
    """Item 3: importing pycolmap handed SIGTERM to glog, which aborted with a C++ stack dump and left
    `.poses.*.partial` behind. The stage is held inside its temporary folder (after pycolmap is loaded) when the
    signal comes. SIGTERM exits with 143, Ctrl-C (SIGINT) still with 130."""
    import shutil
    import signal
    import subprocess
    import sys

    from pipeline.config import PosesConfig
    from pipeline.stages.poses import run_poses

    capture = _capture_copy(tiny_capture, tmp_path / "capture")
    shutil.copy(capture / "ground_truth" / "cameras.json", capture / "cameras.json")  # known cameras: no SfM
    shutil.copytree(capture / "ground_truth" / "masks", capture / "masks")  # the user's masks
    results = tmp_path / "results"
    args = ["poses", capture, "--decode", tiny_decode, "--out", results / "poses"]
    held = "pipeline.stages.poses", "cameras_figure"
    if stage == "masks":
        run_poses(capture, tiny_decode, results / "poses", PosesConfig())
        args = ["masks", capture, "--poses", results / "poses", "--decode", tiny_decode, "--out", results / "masks"]
        held = "pipeline.stages.masks", "contact_sheet"
    marker = tmp_path / "held"
    # Ctrl-C as a terminal gives it: a shell starts background jobs (`pytest ... &`) with SIGINT ignored, and
    # Python keeps that for its children.
    proc = subprocess.Popen([sys.executable, "-c", _HELD_ORCA, *held, str(marker), *map(str, args)],
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    output = _signal_when(proc, marker.exists, f"{stage} inside its temporary folder", signal.Signals[signal_name])
    assert proc.returncode == status, output[-3000:]
    _stopped_cleanly(output, results, signal_name)
    assert not (results / stage).exists()


# `orca ARGS` whose masks workers each write their PID to the file $ORCA_HELD and wait in their first view's sweeps.
# The fork server imports this script as its main module: the patch reaches every worker, the guard keeps `orca`
# itself from running there.
_HELD_WORKERS = """\
import os, sys, time

import pipeline.masking.segment as segment


def hold(*args, **kwargs):
    with open(os.environ["ORCA_HELD"], "a") as f:
        f.write(f"{os.getpid()}\\n")
    time.sleep(600)


segment.view_evidence = hold
if __name__ == "__main__":
    from pipeline.cli import main

    sys.exit(main(sys.argv[1:]))
"""


def _held_masks_workers(tiny_capture, tiny_decode, tmp_path, group: bool = False):
    """`orca masks` with two workers, each held in its first view (:data:`_HELD_WORKERS`): the process, its
    results folder and the workers' PIDs (a callable: empty until both hold)."""
    import os
    import shutil
    import subprocess
    import sys

    from pipeline.config import PosesConfig
    from pipeline.stages.poses import run_poses

    if not Path("/proc/self/status").exists():
        pytest.skip("reads the workers' state from /proc (Linux)")
    capture = _capture_copy(tiny_capture, tmp_path / "capture")
    shutil.copy(capture / "ground_truth" / "cameras.json", capture / "cameras.json")  # known cameras: no SfM
    results = tmp_path / "results"
    run_poses(capture, tiny_decode, results / "poses", PosesConfig())
    marker = tmp_path / "held"
    script = tmp_path / "held_workers.py"
    script.write_text(_HELD_WORKERS)
    args = ["masks", capture, "--poses", results / "poses", "--decode", tiny_decode, "--out", results / "masks",
            "--set", "workers=2"]
    proc = subprocess.Popen([sys.executable, str(script), *map(str, args)], stdout=subprocess.PIPE,
                            stderr=subprocess.STDOUT, text=True, env={**os.environ, "ORCA_HELD": str(marker)},
                            start_new_session=group)

    def workers() -> list[int]:
        pids = marker.read_text().split() if marker.exists() else []
        return [int(p) for p in pids] if len(pids) == 2 else []

    return proc, results, workers


def _ended(pid: int) -> bool:
    """Gone, or a zombie (its parent, the fork server, ended too, and a container's PID 1 may never reap it)."""
    status = Path(f"/proc/{pid}/status")
    return not status.exists() or "State:\tZ" in status.read_text()


@pytest.mark.parametrize("group", [False, True])
def test_sigterm_ends_the_masks_workers_with_the_stage(group, tiny_capture, tiny_decode, tmp_path):
    """The masks stage's views run in worker processes (masks.workers): SIGTERM -- to the stage alone, or to its
    whole process group as Slurm and Snakemake send it -- stops the stage at once (not after the queued views,
    nor after the running ones: each holds for 10 minutes here), leaves no temporary folder and no worker behind."""
    import time

    proc, results, workers = _held_masks_workers(tiny_capture, tiny_decode, tmp_path, group)
    output = _signal_when(proc, workers, "both workers inside a view", group=group)
    assert proc.returncode == 143, output[-3000:]
    _stopped_cleanly(output, results)
    assert not (results / "masks").exists()
    time.sleep(1)
    assert all(_ended(pid) for pid in workers())


def test_the_masks_workers_end_themselves_when_the_stage_is_killed(tiny_capture, tiny_decode, tmp_path):
    """SIGKILL gives the stage no chance to stop its workers: each notices within seconds that the stage is gone
    and ends, instead of computing the views queued for it and then waiting forever."""
    import time

    proc, _, workers = _held_masks_workers(tiny_capture, tiny_decode, tmp_path)
    _signal_when(proc, workers, "both workers inside a view", signum=9)
    deadline = time.time() + 30
    while not all(_ended(pid) for pid in workers()):
        assert time.time() < deadline, "a worker outlived the killed stage by 30 s"
        time.sleep(0.2)


def test_a_masks_worker_that_dies_stops_the_stage_with_the_likely_cause(tiny_capture, tiny_decode, tmp_path):
    """A worker killed mid-view (what the OOM killer does) ends the stage with a message that names the likely
    cause and the fix, not a traceback of the process pool; the other worker ends with it, nothing half-written."""
    import os
    import signal
    import time

    proc, results, workers = _held_masks_workers(tiny_capture, tiny_decode, tmp_path)
    try:
        deadline = time.time() + 300
        while not workers():
            assert proc.poll() is None, proc.communicate()[0][-3000:]
            assert time.time() < deadline, "the workers never held"
            time.sleep(0.1)
        os.kill(workers()[0], signal.SIGKILL)
        output = proc.communicate(timeout=120)[0]
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 2, output[-3000:]
    assert "ended abruptly" in output and "masks.workers=1" in output, output[-3000:]
    assert "Traceback" not in output, output[-3000:]
    assert not list(results.rglob("*.partial")) and not (results / "masks").exists()
    time.sleep(1)
    assert all(_ended(pid) for pid in workers())


def _colmap_model(cameras_json: Path, folder: Path) -> Path:
    """A COLMAP text model of these cameras and of 8 points around the object that every photo sees: what
    `orca train --points` reads (the poses stage's sparse/), without the time SfM takes."""
    import numpy as np
    from scipy.spatial.transform import Rotation

    from pipeline.cameras import load_cameras

    cameras = load_cameras(cameras_json).cameras
    points = [np.array([2 * np.cos(a), 2 * np.sin(a), 0.5]) for a in np.linspace(0, 2 * np.pi, 8, endpoint=False)]
    intrinsics, images = [], []
    for i, c in enumerate(cameras, 1):
        w2c = np.linalg.inv(np.asarray(c.camera_to_world))
        q, t = Rotation.from_matrix(w2c[:3, :3]).as_quat(scalar_first=True), w2c[:3, 3]
        seen = [w2c[:3, :3] @ x + t for x in points]
        intrinsics.append(f"{i} PINHOLE {c.width} {c.height} {c.fx} {c.fy} {c.cx} {c.cy}\n")
        images.append(f"{i} {' '.join(map(str, q))} {' '.join(map(str, t))} {i} {c.name}.png\n"
                      + " ".join(f"{c.fx * p[0] / p[2] + c.cx} {c.fy * p[1] / p[2] + c.cy} {k}"
                                 for k, p in enumerate(seen, 1)) + "\n")
    track = " ".join(f"{i} {{k}}" for i in range(1, len(cameras) + 1))  # (image id, index of its 2D point)
    folder.mkdir()
    (folder / "cameras.txt").write_text("".join(intrinsics))
    (folder / "images.txt").write_text("".join(images))
    (folder / "points3D.txt").write_text("".join(f"{k + 1} {' '.join(map(str, x))} 128 128 128 0.5 "
                                                 f"{track.format(k=k)}\n" for k, x in enumerate(points)))
    return folder


def test_sigterm_checkpoints_train_with_points_and_a_rerun_resumes(tiny_capture, tiny_decode, tmp_path, caplog):
    """Item 3: `orca train --points` (as the Snakefile runs it) loads pycolmap, whose glog aborted on SIGTERM
    with a C++ stack dump: no checkpoint at the signal, the steps since the last one lost."""
    import subprocess
    import sys

    from pipeline.checkpoints import checkpoint_step
    from pipeline.config import load_config
    from pipeline.stages.train import checkpoint_dir_for, run_train

    gt = tiny_capture / "ground_truth"
    points = _colmap_model(gt / "cameras.json", tmp_path / "sparse")
    out = tmp_path / "train"
    overrides = [a for o in [*TINY_TRAIN, "train.iterations=100000", "train.logging.checkpoint_every=100000"]
                 for a in ("--set", o)]
    proc = subprocess.Popen([sys.executable, "-m", "pipeline.cli", "train", "--decode", str(tiny_decode),
                             "--ground-truth", str(gt), "--points", str(points), "--out", str(out),
                             "--preset", "fast", *overrides], stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                            text=True)
    metrics = checkpoint_dir_for(out) / "metrics.jsonl"
    output = _signal_when(proc, lambda: metrics.is_file() and len(metrics.read_text().splitlines()) >= 3,
                          "3 training steps")
    assert proc.returncode == 143, output[-3000:]
    _stopped_cleanly(output, tmp_path)
    assert "sparse depth:" in output  # the points were read: pycolmap was loaded
    ckpts = sorted(checkpoint_dir_for(out).glob("step_*.pt"))
    assert len(ckpts) == 1, "one checkpoint: the one written at the signal"
    step = checkpoint_step(ckpts[0])
    assert step >= 3 and not out.exists()
    cfg = load_config(preset="fast", overrides=[*TINY_TRAIN, f"train.iterations={step + 2}"]).train
    caplog.set_level("INFO")
    resumed = run_train(tiny_decode, gt / "cameras.json", gt / "masks", out, cfg, points_dir=points)
    assert resumed is not None and resumed.iterations == step + 2
    assert f"resuming from {ckpts[0]}" in caplog.text


@pytest.mark.slow(seconds=40)
def test_a_snakemake_run_sigtermed_during_train_resumes_on_rerun(tiny_capture, tmp_path):
    """Item 3: the tiny capture's DAG stopped during train the way Slurm's scancel stops a job (SIGTERM to each of
    its processes; Snakemake itself, sent SIGTERM alone, waits for its running jobs to finish), then rerun: the
    train job checkpointed at the signal, the rerun resumes from there, no temporary folder is left."""
    import contextlib
    import os
    import shutil
    import signal
    import subprocess
    import time

    from pipeline.checkpoints import checkpoint_step

    capture = Path(shutil.copytree(tiny_capture, tmp_path / "captures" / "tiny"))
    shutil.copy(capture / "ground_truth" / "cameras.json", capture / "cameras.json")  # as the DAG test does
    shutil.copytree(capture / "ground_truth" / "masks", capture / "masks")
    results = tmp_path / "results" / "tiny"

    def snakemake(*overrides: str) -> subprocess.Popen:
        cmd = snakemake_command(tmp_path, [*TINY_DAG, "train.logging.log_every=1", *overrides], "results/tiny/train")
        return subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                                start_new_session=True)

    metrics, train_log = results / "train.checkpoints" / "metrics.jsonl", results / "logs" / "train.log"
    first = snakemake("train.iterations=100000", "train.logging.checkpoint_every=100000")
    try:
        output = _signal_when(first, lambda: metrics.is_file() and len(metrics.read_text().splitlines()) >= 2,
                              "training steps", group=True)
        assert first.returncode != 0, output[-3000:]
        deadline = time.time() + 120  # the train job (its shell gone, no one's child) may still be checkpointing
        while "stopped by SIGTERM" not in train_log.read_text() and time.time() < deadline:
            time.sleep(0.2)
    finally:
        with contextlib.suppress(ProcessLookupError):  # a train job that did not stop must not run on for hours
            os.killpg(first.pid, signal.SIGKILL)
    _stopped_cleanly(train_log.read_text(), tmp_path)
    ckpts = sorted((results / "train.checkpoints").glob("step_*.pt"))
    assert len(ckpts) == 1 and not (results / "train").exists(), output[-3000:]
    step = checkpoint_step(ckpts[0])
    rerun = snakemake(f"train.iterations={step + 2}")
    output = rerun.communicate(timeout=600)[0]
    assert rerun.returncode == 0, output[-3000:]
    assert f"resuming from {ckpts[0].relative_to(tmp_path)}" in train_log.read_text()
    assert (results / "train" / "manifest.json").is_file()
    assert not list(tmp_path.rglob("*.partial"))


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


def test_an_empty_user_mask_is_refused_by_the_poses_stage_too(tiny_capture, tiny_decode, tmp_path):
    """Item 5, poses: one black mask carved the object out of the hull the poses stage's sphere comes from."""
    import shutil

    from pipeline.config import PosesConfig
    from pipeline.errors import InputError
    from pipeline.stages.poses import run_poses

    capture = tmp_path / "capture"  # a folder of settings for the decoded photos: known cameras, masks
    capture.mkdir()
    shutil.copy(tiny_capture / "ground_truth" / "cameras.json", capture / "cameras.json")
    names = _true_user_masks(tiny_capture, capture / "masks", blank=_names(tiny_capture)[1:2])
    with pytest.raises(InputError, match=rf"1 of {len(names)} masks are empty \(no object pixel\): {names[1]}.png"):
        run_poses(capture, tiny_decode, tmp_path / "poses", PosesConfig())
    assert not (tmp_path / "poses").exists()


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
    from pipeline.mask_file import read_mask
    from pipeline.training_data import load_image_set

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
        read_mask(rotated / f"{names[0]}.png", (48, 36))
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


def test_inputs_of_another_capture_are_refused(tiny_capture, tmp_path, caplog):
    """Item 7: `orca poses` with another capture's --decode ran, `orca evaluate` against another capture's ground
    truth printed a 22.9 deg pose error with exit 0. Each manifest records its capture; a mismatch stops the
    stage unless --force, and a moved capture (the same photos) is still recognized."""
    import shutil

    from pipeline.artifacts import write_manifest
    from pipeline.provenance import recorded_capture

    a = _capture_copy(tiny_capture, tmp_path / "a")
    b = _capture_copy(tiny_capture, tmp_path / "b")
    photos = sorted(b.glob("IMG_*.dng"))
    shutil.copy(photos[1], photos[0])  # another capture of the same scene: one photo differs
    for capture in (a, b):
        assert _orca("decode", capture, "--out", tmp_path / f"results_{capture.name}" / "decode") == 0
        shutil.copy(capture / "ground_truth" / "cameras.json", capture / "cameras.json")  # known cameras: no SfM
    decode_a, decode_b = tmp_path / "results_a" / "decode", tmp_path / "results_b" / "decode"
    assert recorded_capture(decode_a)["id"] == recorded_capture(a / "ground_truth")["id"], "decode and synth agree"
    assert recorded_capture(decode_a)["id"] != recorded_capture(decode_b)["id"]

    poses = ["--set", "poses.use_masks=false"]
    assert _orca("poses", a, "--decode", decode_b, "--out", tmp_path / "poses", *poses) == 2
    assert "is not the one the other inputs came from" in caplog.text
    assert not (tmp_path / "poses").exists()
    assert _orca("poses", a, "--decode", decode_b, "--out", tmp_path / "poses", *poses, "--force") == 0
    moved = _capture_copy(a, tmp_path / "moved")
    assert _orca("poses", moved, "--decode", decode_a, "--out", tmp_path / "poses_moved", *poses) == 0
    assert recorded_capture(tmp_path / "poses_moved")["id"] == recorded_capture(decode_a)["id"]

    train = write_untrained_train_dir(tmp_path / "train")  # a model of capture b
    write_manifest(train, stage="train", capture=recorded_capture(decode_b))
    caplog.clear()
    assert _orca("evaluate", train, "--ground-truth", a / "ground_truth", "--out", tmp_path / "evaluate") == 2
    assert "the inputs come from different captures" in caplog.text and str(b) in caplog.text



# ---------------------------------------------------------------- tracebacks and misleading messages


def _orca_log(caplog, *args) -> tuple[int, str]:
    """``orca ARGS`` in this process: its exit status and everything it logged (caplog, not the terminal)."""
    from unittest import mock

    from pipeline import cli

    caplog.clear()
    with mock.patch.object(cli, "setup_logging", lambda verbose=False: None), caplog.at_level("INFO"):
        status = cli.main([str(a) for a in args])
    return status, "\n".join(r.getMessage() for r in caplog.records)


def _png_capture(folder: Path, n: int = 3) -> Path:
    """``n`` 16x12 random PNG photos: enough for decode, made in milliseconds."""
    import numpy as np

    from pipeline.imageio import write_png

    rng = np.random.default_rng(0)
    for i in range(n):
        write_png(folder / f"IMG_{i}.png", rng.integers(0, 200, (12, 16, 3), dtype=np.uint8))
    return folder


def _png_decode(tmp_path: Path) -> tuple[Path, Path]:
    from pipeline.config import DecodeConfig
    from pipeline.stages.decode import run_decode

    capture = _png_capture(tmp_path / "cap")
    run_decode(capture, tmp_path / "decode", DecodeConfig())
    return capture, tmp_path / "decode"


def test_a_missing_config_file_is_a_message(tmp_path, caplog):
    """Item 10: `orca decode C --config missing.yaml` was a FileNotFoundError traceback."""
    status, text = _orca_log(caplog, "decode", _png_capture(tmp_path / "cap"), "--config", tmp_path / "missing.yaml")
    assert status == 2
    assert str(tmp_path / "missing.yaml") in text and "not found" in text and text.count("Fix:") == 1


def test_a_cli_option_out_of_range_is_a_message(tmp_path, caplog):
    """Item 10: `orca mesh T --resolution 0` was a raw pydantic ValidationError."""
    status, text = _orca_log(caplog, "mesh", tmp_path / "train", "--resolution", "0")
    assert status == 2
    assert "--resolution 0" in text and "greater than or equal to 16" in text and text.count("Fix:") == 1
    assert "pydantic" not in text


def test_a_damaged_decode_folder_is_a_message_naming_the_file(tmp_path, caplog):
    """Item 10: `orca poses C --decode D` with D/decode.json cut short, or one sRGB PNG deleted, was a
    JSONDecodeError / FileNotFoundError traceback."""
    import shutil

    capture, decode = _png_decode(tmp_path)
    cut = Path(shutil.copytree(decode, tmp_path / "cut"))
    (cut / "decode.json").write_text((decode / "decode.json").read_text()[:100])
    status, text = _orca_log(caplog, "poses", capture, "--decode", cut, "--out", tmp_path / "poses1")
    assert status == 2
    assert str(cut / "decode.json") in text and "`orca decode`" in text and text.count("Fix:") == 1

    (decode / "srgb" / "IMG_1.png").unlink()
    status, text = _orca_log(caplog, "poses", capture, "--decode", decode, "--out", tmp_path / "poses2")
    assert status == 2
    assert "srgb/IMG_1.png" in text and "`orca decode`" in text and text.count("Fix:") == 1
    assert not (tmp_path / "poses1").exists() and not (tmp_path / "poses2").exists()


def test_a_damaged_stage_json_names_the_stage_to_rerun(tmp_path):
    """Item 10: a stage's JSON (cameras.json, a report) cut short was a JSONDecodeError; the fix names the
    stage that wrote it (its folder's manifest), and a capture's own file is the user's to correct."""
    from pipeline.artifacts import write_manifest
    from pipeline.cameras import load_cameras
    from pipeline.errors import InputError
    from pipeline.results import load_poses

    poses = tmp_path / "poses"
    poses.mkdir()
    write_manifest(poses, stage="poses")
    (poses / "cameras.json").write_text('{"cameras": [')
    (poses / "poses_report.json").write_text("{")
    with pytest.raises(InputError, match=r"cameras\.json: not valid JSON .*\nFix: rerun `orca poses`"):
        load_cameras(poses / "cameras.json")
    with pytest.raises(InputError, match=r"poses_report\.json: not valid JSON .*\nFix: rerun `orca poses`"):
        _ = load_poses(poses).report
    (tmp_path / "capture").mkdir()
    (tmp_path / "capture" / "cameras.json").write_text("[")
    with pytest.raises(InputError, match=r"capture/cameras\.json: not valid JSON .*\nFix: correct the file"):
        load_cameras(tmp_path / "capture" / "cameras.json")


def _camera_doc(n: int) -> dict:
    from pipeline.cameras import Camera, CameraSet, look_at

    cams = [Camera(name=f"IMG_{i:04d}", width=32, height=24, fx=30.0, fy=30.0, cx=16.0, cy=12.0,
                   camera_to_world=look_at([3.0, float(i), 1.0], [0.0, 0.0, 0.0]).tolist()) for i in range(n)]
    return CameraSet(cameras=cams).model_dump(mode="json")


def _load_cameras_error(tmp_path, doc) -> str:
    import json

    from pipeline.cameras import load_cameras
    from pipeline.errors import InputError

    path = tmp_path / "cameras.json"
    path.write_text(json.dumps(doc))
    with pytest.raises(InputError) as e:
        load_cameras(path)
    return str(e.value)


def test_a_non_finite_camera_matrix_is_reported_as_such(tmp_path):
    """Item 11: a NaN in a camera matrix read "expected a finite 4x4 matrix, got shape (4, 4)"."""
    doc = _camera_doc(3)
    doc["cameras"][1]["camera_to_world"][2][3] = float("nan")
    text = _load_cameras_error(tmp_path, doc)
    assert "camera IMG_0001: camera_to_world: expected finite numbers, got nan in row 3, column 4" in text
    assert "shape" not in text


def test_a_matrix_of_the_wrong_size_is_reported_as_such(tmp_path):
    """Item 11: a 2x2 transform_matrix in a transforms.json gave numpy's matmul error."""
    import json

    from pipeline.errors import InputError
    from pipeline.transforms import load_transforms

    path = tmp_path / "transforms.json"
    path.write_text(json.dumps({"fl_x": 30, "w": 32, "h": 24, "frames": [
        {"file_path": "images/a.png", "transform_matrix": [[1, 0], [0, 1]]}]}))
    with pytest.raises(InputError, match=r"frame 0 \(images/a.png\): transform_matrix: expected a 4x4 matrix "
                                         r"\(4 rows of 4 numbers\), got 2 rows of 2 numbers") as e:
        load_transforms(path)
    assert "matmul" not in str(e.value)
    doc = _camera_doc(2)
    doc["cameras"][0]["camera_to_world"] = [[1, 0], [0, 1]]
    assert "got 2 rows of 2 numbers" in _load_cameras_error(tmp_path, doc)


def test_a_key_missing_from_every_camera_is_one_line(tmp_path):
    """Item 11: one key missing in a cameras.json gave pydantic's 3 lines per camera (58 for 19 cameras)."""
    doc = _camera_doc(19)
    for cam in doc["cameras"]:
        del cam["height"]
    text = _load_cameras_error(tmp_path, doc)
    assert text.splitlines()[0].endswith("19 cameras (IMG_0000, IMG_0001, IMG_0002, IMG_0003, IMG_0004, ...): "
                                         "height: missing")
    assert len(text.splitlines()) == 2 and text.count("Fix:") == 1 and "pydantic" not in text


def test_config_errors_name_the_source_and_the_closest_key(tmp_path):
    """Item 11: a misspelled key had no "did you mean"; config errors are one line per problem, each naming
    the file or --set it came from."""
    from pipeline.config import load_config, stage_config
    from pipeline.errors import ConfigError

    f = tmp_path / "my.yaml"
    f.write_text("decode:\n  downscal: 2\ntrain:\n  render:\n    env_near: 5\n    env_far: 2\n")
    with pytest.raises(ConfigError) as e:
        load_config(f, overrides=["poses.matcher=vocabulary"])
    lines = str(e.value).splitlines()
    assert lines[0] == "invalid configuration:" and lines[-1].startswith("Fix: ") and len(lines) == 5
    assert f"  {f}: decode.downscal: unknown key; did you mean 'downscale'?" in lines
    assert f"  {f}: train.render: env_far (2.0) must exceed env_near (5.0)" in lines
    assert any(line.startswith("  --set poses.matcher=vocabulary: poses.matcher: input should be") for line in lines)
    with pytest.raises(ConfigError, match=r"--set iteratoins=5: iteratoins: unknown key; did you mean "
                                          r"'train.iterations'\?"):
        stage_config("train", overrides=["iteratoins=5"])


def test_a_bad_preset_in_capture_yaml_names_the_file(tmp_path, caplog):
    """Item 11: `preset: fastt` in capture.yaml did not say which file set it."""
    capture = _png_capture(tmp_path / "cap")
    (capture / "capture.yaml").write_text("preset: fastt\n")
    status, text = _orca_log(caplog, "decode", capture, "--out", tmp_path / "decode")
    assert status == 2
    assert f"{capture / 'capture.yaml'}: unknown preset 'fastt'; did you mean 'fast'?" in text
    assert text.count("Fix:") == 1


def test_unreadable_photos_get_one_fix(tmp_path, caplog):
    """Item 11: "Fix:" was printed once per unreadable photo and once more for all of them."""
    capture = _png_capture(tmp_path / "cap")
    (capture / "IMG_1.png").write_bytes(b"not a png")
    (capture / "IMG_2.png").write_bytes(b"")
    status, text = _orca_log(caplog, "decode", capture, "--out", tmp_path / "decode")
    assert status == 2
    assert "2 of 3 photos cannot be read" in text and "- IMG_1.png: " in text and "- IMG_2.png: " in text
    assert text.count("Fix:") == 1


def test_exif_warnings_name_the_photo(tmp_path, caplog):
    """Item 11: exifread's warnings ("File format not recognized.") did not say which photo; a photo that just
    has no EXIF ("PNG file does not have exif data.", common for PNG exports) is no warning at all."""
    capture = _png_capture(tmp_path / "cap")
    (capture / "IMG_1.png").write_bytes(b"not a png")
    _orca_log(caplog, "decode", capture, "--out", tmp_path / "decode")
    exif = [r.getMessage() for r in caplog.records if r.name == "exifread" and r.levelno >= logging.WARNING]
    assert len(exif) == 1 and exif[0].startswith(f"{capture / 'IMG_1.png'}: EXIF: "), exif


def test_a_damaged_mask_for_training_is_a_message_naming_it(tiny_capture, tiny_decode, tmp_path):
    """`orca train --masks` with a damaged PNG gave a raw ValueError; masks are read by the masks stage's rule."""
    import shutil

    from pipeline.config import load_config
    from pipeline.errors import InputError
    from pipeline.stages.train import run_train

    gt = tiny_capture / "ground_truth"
    masks = Path(shutil.copytree(gt / "masks", tmp_path / "masks"))
    damaged = sorted(masks.glob("*.png"))[0]
    damaged.write_bytes(b"\x89PNG\r\n\x1a\n cut short")
    cfg = load_config(preset="fast", overrides=TINY_TRAIN).train
    with pytest.raises(InputError, match="not a readable image") as e:
        run_train(tiny_decode, gt / "cameras.json", masks, tmp_path / "train", cfg, max_steps=1)
    assert str(damaged) in str(e.value) and str(e.value).count(str(damaged)) == 1
