"""The tree passes ``ruff check`` with the config in pyproject.toml (line length 120, E/F/W/I/UP/B, and
pycolmap imported only through ``pipeline.signals.import_pycolmap``)."""

from __future__ import annotations

import subprocess
import sys

from helpers import ROOT


def test_ruff_check_passes():
    proc = subprocess.run([sys.executable, "-m", "ruff", "check", str(ROOT)], cwd=ROOT, capture_output=True, text=True)
    assert proc.returncode == 0, f"ruff check failed:\n{proc.stdout}{proc.stderr}"
