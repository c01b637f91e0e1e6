"""Shared fixtures: a tiny synthetic capture (rendered once per session) and its decode, the SfM captures.

The suite runs in pytest-xdist workers (scripts/test.sh): a session fixture that renders or runs SfM is made once
per test run by :func:`_once` and shared by the workers, not made again in each."""

from __future__ import annotations

import os
import pickle
import tempfile
from collections import Counter
from collections.abc import Callable
from typing import TypeVar

# LibRaw (rawpy) and torch each bring an OpenMP runtime; with the default spin-waiting, the two fight over
# the cores once both are loaded in one process (a torch test ran 3x slower after the decode tests).
os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")

from pathlib import Path  # noqa: E402

import pytest  # noqa: E402

T = TypeVar("T")


def pytest_collection_modifyitems(items: list[pytest.Item]) -> None:
    """The test files with the longest runs first, by the seconds of their tests' ``slow(seconds=...)`` marks:
    pytest-xdist hands each worker a whole file as it frees up (scripts/test.sh), so a long file begun last would
    leave the other workers idle at the end."""
    seconds: Counter = Counter()
    for item in items:
        mark = item.get_closest_marker("slow")
        seconds[item.path] += mark.kwargs.get("seconds", 0) if mark else 0
    items.sort(key=lambda item: -seconds[item.path])  # stable: each file's tests keep their order


def _once(tmp_path_factory, name: str, make: Callable[[Path], T]) -> T:
    """``make(folder)``'s value (picklable, e.g. a path), made once per test run in a new folder: under
    pytest-xdist the first worker to ask makes it, holding a lock in the run's base folder, and the others read
    what it made. ``make`` must leave the folder as it was made: tests that change it work on a copy."""
    if "PYTEST_XDIST_WORKER" not in os.environ:
        return make(tmp_path_factory.mktemp(name))
    from filelock import FileLock

    base = tmp_path_factory.getbasetemp().parent  # the run's folder, above each worker's own
    value = base / f"{name}.pickle"
    with FileLock(base / f"{name}.lock"):
        if not value.is_file():  # a worker whose make() failed wrote nothing: the next one tries again
            made = make(Path(tempfile.mkdtemp(prefix=f"{name}-", dir=base)))
            value.write_bytes(pickle.dumps(made))
        return pickle.loads(value.read_bytes())


@pytest.fixture(scope="session")
def tiny_capture(tmp_path_factory) -> Path:
    """A 4-view 48x36 glossy-sphere capture with ground truth (coarse textures keep it ~10 s)."""
    pytest.importorskip("mitsuba")
    from helpers import small

    from pipeline.synth import SCENES, SynthOptions, render_capture

    options = SynthOptions(views=4, width=48, height=36, spp=16, env_size=16, coverage_spp=9, seed=1)
    scene = small(SCENES["sphere"])
    return _once(tmp_path_factory, "tiny_capture", lambda folder: render_capture(scene, folder / "sphere", options))


@pytest.fixture(scope="session")
def tiny_decode(tiny_capture, tmp_path_factory) -> Path:
    from pipeline.config import DecodeConfig
    from pipeline.stages.decode import run_decode

    return _once(tmp_path_factory, "tiny_decode",
                 lambda folder: run_decode(tiny_capture, folder / "decode", DecodeConfig()).out_dir)


# The DAG's tiny settings, logged at every step, with a coarser hull and mesh.
TINY_RESULTS = ["train.logging.log_every=1", "train.logging.preview_every=2", "train.device=cpu",
                "masks.hull_resolution=32", "mesh.resolution=24"]


@pytest.fixture(scope="session")
def tiny_results(tiny_capture, tmp_path_factory) -> Path:
    return _once(tmp_path_factory, "tiny_results", lambda folder: _tiny_results(tiny_capture, folder))


def _tiny_results(tiny_capture: Path, folder: Path) -> Path:
    """``results/tiny/`` with every stage's folder but the report's, made by the stages themselves through the
    `orca` CLI: decode, poses (the capture's known cameras), masks (its own masks), a few training steps, mesh,
    export and evaluate (~15 s). Tests that change it work on a copy."""
    import shutil

    from helpers import TINY_DAG

    from pipeline.cli import main

    capture = folder / "captures" / "tiny"
    shutil.copytree(tiny_capture, capture)
    shutil.copy(capture / "ground_truth" / "cameras.json", capture / "cameras.json")
    shutil.copytree(capture / "ground_truth" / "masks", capture / "masks")
    out = folder / "results" / "tiny"
    sets = [a for s in [*TINY_DAG, *TINY_RESULTS] for a in ("--set", s)]
    cams = str(out / "masks" / "cameras.json")
    for argv in (
        ["decode", str(capture), "--out", str(out / "decode")],
        ["poses", str(capture), "--decode", str(out / "decode"), "--out", str(out / "poses")],
        ["masks", str(capture), "--poses", str(out / "poses"), "--decode", str(out / "decode"), "--out",
         str(out / "masks")],
        ["train", "--decode", str(out / "decode"), "--cameras", cams, "--masks", str(out / "masks" / "masks"),
         "--capture", str(capture), "--out", str(out / "train")],
        ["mesh", str(out / "train"), "--cameras", cams, "--out", str(out / "mesh"), "--device", "cpu"],
        ["export", str(out / "train"), "--cameras", cams, "--out", str(out / "export"), "--device", "cpu"],
    ):
        assert main([*argv, "--preset", "fast", *sets]) == 0, argv[0]
    assert main(["evaluate", str(out / "train"), "--ground-truth", str(capture / "ground_truth"), "--cameras", cams,
                 "--mesh", str(out / "mesh" / "mesh.ply"), "--out", str(out / "evaluate"), "--views", "1",
                 "--downscale", "2", "--device", "cpu"]) == 0
    return out


@pytest.fixture
def float64():
    """Run a test with float64 as torch's default dtype, restoring the previous default afterwards
    (a module-level ``set_default_dtype`` would leak into every test collected after it)."""
    import torch

    old = torch.get_default_dtype()
    torch.set_default_dtype(torch.float64)
    yield
    torch.set_default_dtype(old)


def _sfm_capture(tmp_path_factory, scene: str, views: int, spp: int, seed: int) -> Path:
    """A JPEG capture big enough for SfM: 320x240 with the scene's full room textures (``helpers.small``'s
    coarse textures leave too few SIFT features: 20 views at 160x120 or with coarse textures do not register)."""
    pytest.importorskip("mitsuba")
    from pipeline.synth import SCENES, SynthOptions, render_capture

    options = SynthOptions(views=views, width=320, height=240, spp=spp, format="jpg", env_size=16, coverage_spp=4,
                           seed=seed)
    return _once(tmp_path_factory, f"sfm_{scene}",
                 lambda folder: render_capture(SCENES[scene], folder / scene, options))


def _decode(capture: Path, tmp_path_factory) -> Path:
    from pipeline.config import DecodeConfig
    from pipeline.stages.decode import run_decode

    return _once(tmp_path_factory, f"{capture.name}_decode",
                 lambda folder: run_decode(capture, folder / "decode", DecodeConfig()).out_dir)


@pytest.fixture(scope="session")
def sfm_sphere_capture(tmp_path_factory) -> Path:
    """20 views of the glossy sphere at 320x240 (~45 s to render); SfM registers all of them."""
    return _sfm_capture(tmp_path_factory, "sphere", views=20, spp=8, seed=0)


@pytest.fixture(scope="session")
def sfm_sphere_decode(sfm_sphere_capture, tmp_path_factory) -> Path:
    return _decode(sfm_sphere_capture, tmp_path_factory)


@pytest.fixture(scope="session")
def sfm_sphere_poses(sfm_sphere_capture, sfm_sphere_decode, tmp_path_factory):
    """The poses stage (SfM) on the sphere capture: (its result, its folder, seconds taken)."""
    import time

    from pipeline.config import PosesConfig
    from pipeline.stages.poses import run_poses

    def poses(folder: Path):
        started = time.time()
        result = run_poses(sfm_sphere_capture, sfm_sphere_decode, folder / "poses", PosesConfig(num_threads=2))
        return result, folder / "poses", time.time() - started

    return _once(tmp_path_factory, "sfm_sphere_poses", poses)


@pytest.fixture(scope="session")
def sfm_torus_capture(tmp_path_factory) -> Path:
    """20 views of the glossy torus (non-convex) at 320x240, 4 samples per pixel (~30 s to render)."""
    return _sfm_capture(tmp_path_factory, "torus", views=20, spp=4, seed=1)


@pytest.fixture(scope="session")
def sfm_torus_decode(sfm_torus_capture, tmp_path_factory) -> Path:
    return _decode(sfm_torus_capture, tmp_path_factory)
