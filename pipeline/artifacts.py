"""Atomic artifacts: a stage writes into a temporary sibling and renames it into place at the end.

An interrupted stage therefore never leaves a half-written file or folder that a later stage could trust.
Each stage folder also carries ``manifest.json``: inputs' hashes, the config used, versions, timing.
"""

from __future__ import annotations

import contextlib
import hashlib
import json
import logging
import os
import platform
import re
import shutil
import socket
import tempfile
import time
from collections.abc import Iterable, Iterator, Mapping
from importlib import metadata
from pathlib import Path
from typing import Any

from .errors import InputError
from .layout import MANIFEST

log = logging.getLogger("orca")


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def _as_if_created(path: Path, base_mode: int) -> None:
    """tempfile creates files 0600 and folders 0700 (private); an artifact gets the modes ``open`` and
    ``mkdir`` would have given it, so other users and tools (a web server for the report) can read it."""
    path.chmod(base_mode & ~_umask())


@contextlib.contextmanager
def atomic_path(path: str | Path) -> Iterator[Path]:
    """Yield a temporary file path beside ``path``; rename it onto ``path`` only if the block succeeds."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=_temporary_prefix(path.name), suffix=".tmp" + path.suffix, dir=path.parent)
    os.close(fd)
    tmp = Path(tmp)
    _as_if_created(tmp, 0o666)
    try:
        yield tmp
        os.replace(tmp, path)
    finally:
        tmp.unlink(missing_ok=True)


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # another user's live process
        return True
    return True


_HOST = socket.gethostname().split(".")[0].replace("-", "_") or "host"


def _writer_gone(host: str | None, pid: str | None) -> bool:
    """Whether the writer a temporary's name records (``<host>-<pid>``) has stopped: it ran on this machine and
    its process is gone. A name without a writer (earlier versions) counts as stopped; one of another machine
    cannot be checked and does not."""
    return host in (None, _HOST) and (pid is None or not _alive(int(pid)))


def _temporary_prefix(name: str) -> str:
    """``.<name>.<host>-<pid>.``: whoever finds the folder later can tell whether its writer still runs."""
    return f".{name}.{_HOST}-{os.getpid()}."


def remove_stale_temporaries(path: str | Path) -> list[Path]:
    """Remove the temporary siblings (``.<name>.*.partial``, ``.<name>.old-*``) that an earlier run writing
    ``path`` left behind when it was killed (SIGKILL, power loss). Those of a writer still running on this
    machine are kept, and so are those of other machines (a shared file system): their writers cannot be checked.

    Returns:
        the folders removed.
    """
    path = Path(path)
    if not path.parent.is_dir():
        return []
    removed = []
    pattern = re.compile(rf"^\.{re.escape(path.name)}\.(?:(?P<host>\w+)-(?P<pid>\d+)\..*\.partial|.*\.partial|"
                         rf"old-(?P<old>\d+))$")
    for entry in path.parent.iterdir():
        m = pattern.match(entry.name)
        if not m or not entry.is_dir():
            continue
        if not _writer_gone(m["host"], m["pid"] or m["old"]):
            continue
        shutil.rmtree(entry, ignore_errors=True)
        removed.append(entry)
    if removed:
        log.info("removed %d temporary folder(s) an interrupted run left beside %s: %s", len(removed), path,
                 ", ".join(p.name for p in removed))
    return removed


def remove_stale_temporary_files(folder: str | Path) -> list[Path]:
    """Remove the temporary files (:func:`atomic_path`'s) that killed runs left in ``folder``; those of writers
    still running on this machine, or of other machines, are kept."""
    folder = Path(folder)
    pattern = re.compile(r"^\..+\.(?P<host>\w+)-(?P<pid>\d+)\.[^.]+\.tmp(\.\w+)?$")
    removed = []
    for entry in folder.iterdir() if folder.is_dir() else ():
        m = pattern.match(entry.name)
        if m and entry.is_file() and _writer_gone(m["host"], m["pid"]):
            entry.unlink(missing_ok=True)
            removed.append(entry)
    if removed:
        log.info("removed %d temporary file(s) an interrupted run left in %s", len(removed), folder)
    return removed


def check_output_dir(path: str | Path, stage: str, inputs: Iterable[str | Path] = (), *,
                     manifest: str = MANIFEST) -> Path:
    """Refuse an output folder that a stage may not replace: it replaces ``path`` whole, so ``path`` must be
    absent, empty, or a folder this same stage wrote (its ``manifest`` names ``stage``), and it may not be,
    hold, or lie inside any of the stage's ``inputs``.

    Raises:
        InputError: naming the folder and the fix; nothing is touched.
    """
    path = Path(path)
    out = path.resolve()
    for parent in out.parents:
        if parent.exists() and not parent.is_dir():
            raise InputError(f"{parent} is a file, so no folder can be made inside it", path,
                             "choose an output folder whose parent folders are folders")
    for given in inputs:
        source = Path(given).resolve()
        if out == source or out in source.parents or source in out.parents:
            where = ("is" if out == source else "holds" if out in source.parents else "lies inside")
            raise InputError(f"the output folder {where} the {stage} stage's input {given}: writing it would "
                             "replace that input", path, "choose an output folder apart from the inputs, e.g. "
                             f"results/<capture>/{stage}")
    if not path.exists():
        return path
    if not path.is_dir():
        raise InputError(f"exists and is a file, not a {stage} stage folder; refusing to replace it", path,
                         "choose another output folder, or move the file away")
    if any(path.iterdir()) and _stage_of(path / manifest) != stage:
        raise InputError(f"holds files the {stage} stage did not write (no {manifest} of a {stage} run in it); "
                         "refusing to replace them", path,
                         "choose a new or empty output folder, or move those files away")
    return path


def _stage_of(manifest: Path) -> str | None:
    try:
        return read_json(manifest).get("stage")
    except (OSError, ValueError, AttributeError):
        return None


@contextlib.contextmanager
def atomic_dir(path: str | Path, stage: str, inputs: Iterable[str | Path] = (), *,
               manifest: str = MANIFEST) -> Iterator[Path]:
    """Yield a temporary folder beside ``path``; on success it replaces ``path`` whole, on error it is removed.

    ``path`` must pass :func:`check_output_dir` (absent, empty, or this ``stage``'s earlier result, apart from its
    ``inputs``); an existing ``path`` survives a failed run untouched. Temporary folders that killed runs left
    beside ``path`` are removed first.
    """
    path = check_output_dir(path, stage, inputs, manifest=manifest)
    path.parent.mkdir(parents=True, exist_ok=True)
    remove_stale_temporaries(path)
    tmp = Path(tempfile.mkdtemp(prefix=_temporary_prefix(path.name), suffix=".partial", dir=path.parent))
    _as_if_created(tmp, 0o777)
    try:
        yield tmp
        check_output_dir(path, stage, manifest=manifest)  # nothing else has moved in meanwhile
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


def read_stage_json(path: str | Path, stage: str | None = None) -> Any:
    """A JSON file a stage wrote. Missing or damaged (an interrupted copy, an edit gone wrong), it is an
    :class:`InputError` naming the file and the stage to rerun (:func:`rerun_fix`), not a traceback."""
    path = Path(path)
    try:
        return read_json(path)
    except FileNotFoundError as e:
        raise InputError("file not found", path, rerun_fix(path, stage)) from e
    except (OSError, ValueError) as e:  # JSONDecodeError and UnicodeDecodeError are ValueErrors
        raise InputError(f"not valid JSON ({e})", path, rerun_fix(path, stage)) from e


def rerun_fix(path: Path, stage: str | None = None) -> str:
    """What to do about a damaged stage output: rerun the stage the manifest beside it names (or the one of
    the folder above: poses/undistorted/ is the poses stage's), else ``stage``. A file no stage wrote (a
    capture's own cameras.json) is the user's to correct."""
    stage = _writer(path) or stage
    if stage is None:
        return "correct the file"
    return f"rerun `orca {stage}` (or snakemake --forcerun {stage})"


def _writer(path: Path) -> str | None:
    for folder in (path.parent, path.parent.parent):
        try:
            return str(read_json(folder / MANIFEST)["stage"])
        except (OSError, ValueError, KeyError, TypeError):
            continue
    return None


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
    capture: Mapping[str, Any] | None = None,
) -> Path:
    """Write ``manifest.json`` into a stage folder: input hashes, config, versions, timing."""
    manifest: dict[str, Any] = {
        "stage": stage,
        "created": time.strftime("%Y-%m-%dT%H:%M:%S%z"),
        "inputs": {str(k): {"path": str(v), "sha256": file_sha256(v)} for k, v in (inputs or {}).items()},
        "config": dict(config or {}),
        "versions": versions(),
    }
    if capture is not None:  # see pipeline.provenance
        manifest["capture"] = dict(capture)
    if started is not None:
        manifest["seconds"] = round(time.time() - started, 3)
    if extra:
        manifest.update(extra)
    return write_json(Path(folder) / MANIFEST, manifest)
