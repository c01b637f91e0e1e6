"""SIGTERM stops a stage the way Ctrl-C does.

Slurm, Snakemake and ``kill`` stop a job with SIGTERM, whose default ends the process on the spot: training would
lose the steps since its last checkpoint, a stage would leave its temporary folder behind. Raised as
:class:`Terminated` (a ``KeyboardInterrupt``) instead, it unwinds like Ctrl-C: train saves a checkpoint, every
stage removes its temporary folder, and ``orca`` exits with 143 (128 + 15; Ctrl-C gives 130).

Importing pycolmap takes SIGTERM over (its glog installs a failure-signal handler that prints a C++ stack dump
and aborts), so pycolmap is imported through :func:`import_pycolmap` only; ruff (TID251) holds every import to it.
"""

from __future__ import annotations

import signal
import threading
from types import ModuleType


class Terminated(KeyboardInterrupt):
    """SIGTERM arrived; raised in the main thread wherever it was, as Ctrl-C raises ``KeyboardInterrupt``."""


# Set by the handler, cleared once the stop is raised again or handled. Python swallows an exception raised while a
# finalizer runs (``__del__``, a weakref callback: printed as "Exception ignored in ...") -- a SIGTERM landing
# there would be lost, and with SIGTERM ignored from then on the stage would run to its end.
_pending = threading.Event()


def _raise_terminated(signum: int, frame: object) -> None:
    # One unwinding is enough: a second SIGTERM would break off the checkpoint or the clean-up it is running.
    signal.signal(signal.SIGTERM, signal.SIG_IGN)
    _pending.set()
    raise Terminated("SIGTERM")


def raise_if_terminated() -> None:
    """Raise :class:`Terminated` if a SIGTERM arrived whose exception was swallowed (see ``_pending``). Long loops
    call it once per step; :func:`pipeline.log.progress` bars call it on every advance and update."""
    if _pending.is_set():
        _pending.clear()
        raise Terminated("SIGTERM")


def stop_on_sigterm() -> None:
    """From now on, SIGTERM raises :class:`Terminated` in the main thread (call it from the main thread)."""
    signal.signal(signal.SIGTERM, _raise_terminated)


def stopped_by(interrupt: KeyboardInterrupt) -> signal.Signals:
    """The signal behind a ``KeyboardInterrupt``: SIGTERM for :class:`Terminated`, else SIGINT (Ctrl-C). The stop
    is handled: it is not raised again."""
    _pending.clear()
    return signal.SIGTERM if isinstance(interrupt, Terminated) else signal.SIGINT


def import_pycolmap() -> ModuleType:
    """pycolmap, with SIGTERM handled as it was before the first import (glog's handler replaced it).

    Python can only set handlers from the main thread: a first import from another thread keeps glog's.
    """
    handler = signal.getsignal(signal.SIGTERM)
    import pycolmap  # noqa: TID251 - the one import that puts the handler back

    if handler is not None and threading.current_thread() is threading.main_thread():
        signal.signal(signal.SIGTERM, handler)
    return pycolmap
