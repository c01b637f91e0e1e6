"""The ``orca`` command (pipeline.cli): every stage listed, each with help and examples."""

from __future__ import annotations

import subprocess
import sys


def test_cli_lists_stages_and_each_has_help_with_examples():
    from pipeline.cli import COMMANDS

    top = subprocess.run([sys.executable, "-m", "pipeline.cli", "--help"], capture_output=True, text=True)
    assert top.returncode == 0
    for name, _ in COMMANDS:
        assert name in top.stdout
        sub = subprocess.run([sys.executable, "-m", "pipeline.cli", name, "--help"], capture_output=True, text=True)
        assert sub.returncode == 0, sub.stderr
        assert "example" in sub.stdout.lower(), f"`orca {name} --help` should show examples"
