"""Stage folders (pipeline.artifacts): written atomically with the modes of plain files, manifests with input
hashes and versions, JSON of numpy values."""

from __future__ import annotations

import os
import stat

import numpy as np
import pytest

from pipeline.artifacts import atomic_dir, read_json, write_json, write_manifest


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
