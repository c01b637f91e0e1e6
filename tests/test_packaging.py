"""What installs: constraints.txt pins every dependency pyproject.toml declares (extras too) within its bounds and
leaves torch to scripts/setup.sh; mitsuba is the synth extra, imported by pipeline/synth alone, and its absence is a
clear error; the nerfstudio constraints keep the two OpenCV distributions at one version."""

from __future__ import annotations

import re
import sys

import pytest
from helpers import ROOT
from packaging.requirements import Requirement
from packaging.utils import canonicalize_name
from packaging.version import Version

from pipeline.errors import OrcaError


def _pins(path) -> dict[str, Version]:
    """``name == version`` lines of a constraints file, by canonical name."""
    pins = {}
    for line in path.read_text().splitlines():
        line = line.split("#", 1)[0].strip()
        if line:
            req = Requirement(line)
            (spec,) = req.specifier
            assert spec.operator == "==", line
            pins[canonicalize_name(req.name)] = Version(spec.version)
    return pins


def _project() -> dict:
    tomllib = pytest.importorskip("tomllib")  # Python 3.11+
    return tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]


def _requirements(extras: set[str] | None = None, base: bool = True) -> list[Requirement]:
    """pyproject.toml's dependencies (``base``) and those of ``extras`` (default: every extra) and of the extras
    they name (a test extra naming orca-capture[cluster])."""
    project = _project()
    optional = project["optional-dependencies"]
    todo, seen, reqs = list(optional if extras is None else extras), set(), []
    reqs += [Requirement(r) for r in project["dependencies"]] if base else []
    while todo:
        extra = todo.pop()
        if extra not in seen:
            seen.add(extra)
            for req in map(Requirement, optional[extra]):
                if canonicalize_name(req.name) == "orca-capture":
                    todo += list(req.extras)
                else:
                    reqs.append(req)
    return reqs


def _setup_extras() -> set[str]:
    """The extras scripts/setup.sh installs (``-e "$ROOT[test,synth]"``)."""
    (found,) = re.findall(r'-e "\$ROOT\[([\w,]+)\]"', (ROOT / "scripts" / "setup.sh").read_text())
    return set(found.split(","))


def test_constraints_pin_every_dependency_setup_installs_within_pyproject_bounds_but_torch():
    pins = _pins(ROOT / "constraints.txt")
    assert "torch" not in pins  # setup.sh installs the build ORCA_TORCH names (CPU or CUDA) before the rest
    assert {"test", "synth"} <= _setup_extras()
    for req in _requirements(_setup_extras()):
        name = canonicalize_name(req.name)
        if name == "torch":
            continue
        assert name in pins, f"constraints.txt does not pin {req.name} (regenerate it: see its header)"
        assert req.specifier.contains(pins[name], prereleases=True), f"{req}: constraints.txt has {pins[name]}"


def test_setup_installs_with_the_constraints_and_the_synth_extra():
    setup = (ROOT / "scripts" / "setup.sh").read_text()
    assert 'CONSTRAINTS="${ORCA_CONSTRAINTS-$ROOT/constraints.txt}"' in setup
    install = [line for line in setup.splitlines() if " install " in line and "-e " in line]
    assert len(install) == 1 and '"${CONSTRAINT_ARGS[@]}"' in install[0] and "synth" in install[0], install


def test_mitsuba_is_an_extra_imported_by_synth_alone():
    assert [r.name for r in _requirements({"synth"}, base=False)] == ["mitsuba"]
    assert not [r for r in map(Requirement, _project()["dependencies"]) if r.name == "mitsuba"]
    importing = [p.relative_to(ROOT).as_posix() for folder in ("orca", "pipeline", "calibration")
                 for p in (ROOT / folder).rglob("*.py")
                 if re.search(r"^\s*(import mitsuba|from mitsuba)", p.read_text(), re.MULTILINE)]
    assert importing == ["pipeline/synth/build.py"]


def test_missing_mitsuba_says_how_to_install_it(monkeypatch):
    from pipeline.synth import build

    monkeypatch.setitem(sys.modules, "mitsuba", None)  # what `import mitsuba` meets when it is not installed
    with pytest.raises(OrcaError) as error:
        build.mitsuba()
    assert "Mitsuba 3" in error.value.message and ".[synth]" in error.value.fix


def test_nerfstudio_constraints_keep_both_opencv_distributions_at_one_version():
    pins = _pins(ROOT / "constraints-nerfstudio.txt")
    assert pins["opencv-contrib-python-headless"] == pins["opencv-python-headless"]
    opencv = next(r for r in _requirements() if canonicalize_name(r.name) == "opencv-contrib-python-headless")
    assert opencv.specifier.contains(pins["opencv-contrib-python-headless"])
    pycolmap = next(r for r in _requirements() if canonicalize_name(r.name) == "pycolmap")
    assert pycolmap.specifier.contains(pins["pycolmap"]) and pins["pycolmap"] == _pins(ROOT / "constraints.txt")[
        "pycolmap"]


def test_setup_gives_pip_back_to_an_environment_whose_creation_was_interrupted(tmp_path):
    """``python -m venv`` installs pip last: stopped before that, the environment has a python and no pip, and every
    later set-up failed with "No module named pip". Set-up installs pip into it, and installs nothing else when the
    environment's stamp says it is current (an unknown ORCA_TORCH makes any install fail, and the test with it)."""
    import hashlib
    import os
    import subprocess

    venv, torch = tmp_path / "venv", "orca-no-such-package==0"
    subprocess.run([sys.executable, "-m", "venv", "--without-pip", str(venv)], check=True)
    definition = b"".join((ROOT / name).read_bytes() for name in ("pyproject.toml", "scripts/setup.sh",
                                                                    "constraints.txt"))
    (venv / ".orca-setup-stamp").write_text(f"{hashlib.sha256(definition).hexdigest()[:16]} {torch}\n")
    done = subprocess.run(["bash", str(ROOT / "scripts" / "setup.sh")], capture_output=True, text=True,
                          env={**os.environ, "ORCA_VENV": str(venv), "ORCA_TORCH": torch, "ORCA_CONSTRAINTS": str(
                              ROOT / "constraints.txt")})
    assert done.returncode == 0, done.stderr[-2000:]
    assert "no pip" in done.stderr and "environment up to date" in done.stderr
    subprocess.run([str(venv / "bin" / "python"), "-m", "pip", "--version"], check=True, capture_output=True)
