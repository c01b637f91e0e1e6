"""Errors a user can act on: each names the offending file and the fix."""

from __future__ import annotations

from pathlib import Path


class OrcaError(Exception):
    """Base class for errors the CLI reports as a clean message instead of a traceback."""


class InputError(OrcaError):
    """Bad user input (a file, a folder, a config value)."""

    def __init__(self, message: str, path: str | Path | None = None, fix: str | None = None):
        self.path = Path(path) if path is not None else None
        self.fix = fix
        parts = [f"{self.path}: {message}" if self.path is not None else message]
        if fix:
            parts.append(f"Fix: {fix}")
        super().__init__("\n".join(parts))


class ConfigError(OrcaError):
    """A configuration file or value that does not validate."""
