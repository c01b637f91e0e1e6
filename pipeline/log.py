"""Readable logs (rich) and progress bars for long work."""

from __future__ import annotations

import contextlib
import logging
import os
import sys
from collections.abc import Iterator
from typing import Any

from rich.console import Console
from rich.logging import RichHandler
from rich.progress import (
    BarColumn,
    MofNCompleteColumn,
    Progress,
    TaskID,
    TextColumn,
    TimeElapsedColumn,
    TimeRemainingColumn,
)

from .signals import raise_if_terminated

console = Console(stderr=True)


def setup_logging(verbose: bool = False) -> None:
    level = logging.DEBUG if verbose else logging.INFO
    logging.basicConfig(
        level=level,
        format="%(message)s",
        datefmt="[%X]",
        handlers=[RichHandler(console=console, show_path=False, rich_tracebacks=True)],
        force=True,
    )


class _StoppableProgress(Progress):
    """A rich progress bar whose every step first raises a SIGTERM that a finalizer swallowed
    (:func:`pipeline.signals.raise_if_terminated`): the stage stops at its next step, as it would have."""

    def advance(self, task_id: TaskID, advance: float = 1) -> None:
        raise_if_terminated()
        super().advance(task_id, advance)

    def update(self, task_id: TaskID, **kwargs: Any) -> None:
        raise_if_terminated()
        super().update(task_id, **kwargs)


def progress() -> Progress:
    """A progress bar (hidden when stderr is not a terminal, e.g. under CI or Snakemake logs)."""
    return _StoppableProgress(
        TextColumn("[bold]{task.description}"),
        BarColumn(),
        MofNCompleteColumn(),
        TimeElapsedColumn(),
        TimeRemainingColumn(),
        console=console,
        disable=not sys.stderr.isatty() or bool(os.environ.get("ORCA_NO_PROGRESS")),
    )


class _Collector(logging.Handler):
    def __init__(self) -> None:
        super().__init__(logging.WARNING)
        self.messages: list[str] = []

    def emit(self, record: logging.LogRecord) -> None:
        self.messages.append(record.getMessage())


@contextlib.contextmanager
def collect_warnings(logger: logging.Logger) -> Iterator[list[str]]:
    """The warnings ``logger`` (and its children) log inside the block, for a stage's report: a person reads
    the JSON, not the log."""
    handler = _Collector()
    logger.addHandler(handler)
    try:
        yield handler.messages
    finally:
        logger.removeHandler(handler)
