"""Atomic artifacts: a stage writes into a temporary sibling and renames it into place at the end.

An interrupted stage therefore never leaves a half-written file or folder that a later stage could trust.
Each stage folder also carries ``manifest.json``: inputs' hashes, the config used, versions, timing.
"""

from __future__ import annotations

import contextlib
import hashlib
import json
import os
import platform
import shutil
import tempfile
import time
from collections.abc import Iterator, Mapping
from importlib import metadata
from pathlib import Path
from typing import Any

MANIFEST = "manifest.json"


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def _as_if_created(path: Path, base_mode: int) -> None:
    """tempfile creates files 0600 and folders 0700 (private); an artifact gets the modes ``open`` and
    ``mkdir`` would have given it, so other users and tools (a web server for the report) can read it."""
    path.chmod(base_mode & ~_umask())


def stage_dir(capture: str | Path, stage: str, given: str | Path | None = None) -> Path:
    """A stage's folder: ``given`` when set, else ``results/<capture folder name>/<stage>`` (the CLI default,
    the Snakefile's layout)."""
    return Path(given) if given is not None else Path("results") / Path(capture).resolve().name / stage


@contextlib.contextmanager
def atomic_path(path: str | Path) -> Iterator[Path]:
    """Yield a temporary file path beside ``path``; rename it onto ``path`` only if the block succeeds."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp" + path.suffix, dir=path.parent)
    os.close(fd)
    tmp = Path(tmp)
    _as_if_created(tmp, 0o666)
    try:
        yield tmp
        os.replace(tmp, path)
    finally:
        tmp.unlink(missing_ok=True)


@contextlib.contextmanager
def atomic_dir(path: str | Path) -> Iterator[Path]:
    """Yield a temporary folder beside ``path``; on success it replaces ``path`` whole, on error it is removed.

    An existing ``path`` survives a failed run untouched.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=f".{path.name}.", suffix=".partial", dir=path.parent))
    _as_if_created(tmp, 0o777)
    try:
        yield tmp
        if path.exists():
            old = path.with_name(f".{path.name}.old-{os.getpid()}")
            os.replace(path, old)
            os.replace(tmp, path)
            shutil.rmtree(old, ignore_errors=True)
        else:
            os.replace(tmp, path)
    finally:
        if tmp.exists():
            shutil.rmtree(tmp, ignore_errors=True)


def write_json(path: str | Path, data: Any) -> Path:
    """Write JSON (indented, UTF-8) atomically."""
    path = Path(path)
    with atomic_path(path) as tmp:
        tmp.write_text(json.dumps(data, indent=2, default=_json_default) + "\n", encoding="utf-8")
    return path


def read_json(path: str | Path) -> Any:
    return json.loads(Path(path).read_text(encoding="utf-8"))


def _json_default(obj: Any) -> Any:
    import numpy as np

    if isinstance(obj, np.ndarray):
        return obj.tolist()
    if isinstance(obj, np.generic):
        return obj.item()
    if isinstance(obj, Path):
        return str(obj)
    raise TypeError(f"not JSON serializable: {type(obj).__name__}")


def file_sha256(path: str | Path, chunk: int = 1 << 20) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as f:
        while block := f.read(chunk):
            h.update(block)
    return h.hexdigest()


def versions() -> dict[str, str]:
    """Versions of the libraries whose behaviour shapes the artifacts."""
    out = {"python": platform.python_version()}
    for name in ("orca-capture", "numpy", "torch", "rawpy", "pycolmap", "open3d", "mitsuba", "openexr"):
        out[name] = _version(name)
    return out


def _version(name: str) -> str:
    try:
        return metadata.version(name)
    except metadata.PackageNotFoundError:
        return "not installed"


def write_manifest(
    folder: str | Path,
    *,
    stage: str,
    inputs: Mapping[str, str | Path] | None = None,
    config: Mapping[str, Any] | None = None,
    started: float | None = None,
    extra: Mapping[str, Any] | None = None,
) -> Path:
    """Write ``manifest.json`` into a stage folder: input hashes, config, versions, timing."""
    manifest: dict[str, Any] = {
        "stage": stage,
        "created": time.strftime("%Y-%m-%dT%H:%M:%S%z"),
        "inputs": {str(k): {"path": str(v), "sha256": file_sha256(v)} for k, v in (inputs or {}).items()},
        "config": dict(config or {}),
        "versions": versions(),
    }
    if started is not None:
        manifest["seconds"] = round(time.time() - started, 3)
    if extra:
        manifest.update(extra)
    return write_json(Path(folder) / MANIFEST, manifest)
