"""Errors a user can act on: each names the offending file and the fix."""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any


class OrcaError(Exception):
    """Base class for errors the CLI reports as a clean message instead of a traceback.

    ``message`` says what is wrong, ``path`` the file or folder it is about, ``fix`` what to do; an error that
    gathers others (every unreadable photo) lists their ``path: message`` and gives one fix for all.
    """

    def __init__(self, message: str, path: str | Path | None = None, fix: str | None = None):
        self.message = message
        self.path = Path(path) if path is not None else None
        self.fix = fix
        parts = [f"{self.path}: {message}" if self.path is not None else message]
        if fix:
            parts.append(f"Fix: {fix}")
        super().__init__("\n".join(parts))


class InputError(OrcaError):
    """Bad user input (a file, a folder, a config value)."""


class ConfigError(OrcaError):
    """A configuration file or value that does not validate."""


def validation_problem(error: Mapping[str, Any]) -> str:
    """One item of a pydantic ``ValidationError.errors()`` as a short phrase: what is wrong and the value given,
    without pydantic's type codes, input dumps and links (a person reads it, one line per problem)."""
    kind, message = error["type"], str(error["msg"])
    if kind == "missing":
        return "missing"
    if kind == "extra_forbidden":
        return "unknown key"
    if message.startswith("Value error, "):  # our validators' own messages say what they got
        return message.removeprefix("Value error, ")
    return f"{message[:1].lower()}{message[1:]} (got {_short(error.get('input'))})"


def _short(value: Any, limit: int = 60) -> str:
    text = repr(value)
    return text if len(text) <= limit else text[: limit - 3] + "..."
