"""Per-view work of the masks in worker processes. Every view's sweeps, evidence against the hull and GrabCut are
independent of the other views' in the same step, and they are many small OpenCV and numpy calls that hold
Python's lock between them: threads do not overlap them, processes do.

A :data:`MapViews` runs ``fn(*task)`` for each task and returns the results in order, calling ``done`` after each;
:func:`serial` does it here, :func:`view_workers` in a pool. Results are the same either way: each call depends
only on its task (GrabCut seeds its own random generator)."""

from __future__ import annotations

import multiprocessing
import os
import signal
import threading
import time
from collections.abc import Callable, Iterator, Sequence
from concurrent.futures import ProcessPoolExecutor
from concurrent.futures.process import BrokenProcessPool
from contextlib import contextmanager
from pathlib import Path
from typing import Any, TypeVar

import cv2
from threadpoolctl import threadpool_limits

from ..errors import OrcaError

T = TypeVar("T")
ORPHAN_CHECK_S = 1.0  # how often a worker looks whether the stage that started it still runs
MapViews = Callable[[Callable[..., T], Sequence[tuple[Any, ...]], Callable[[], None]], list[T]]


def serial(fn: Callable[..., T], tasks: Sequence[tuple[Any, ...]], done: Callable[[], None] = lambda: None
           ) -> list[T]:
    """``[fn(*task) for task in tasks]``, calling ``done`` after each."""
    out = []
    for task in tasks:
        out.append(fn(*task))
        done()
    return out


def usable_cores() -> int:
    """The cores this process may run on (its affinity, e.g. a Slurm allocation), not the machine's."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # not Linux
        return os.cpu_count() or 1


def _worker_start(stage: int) -> None:
    # As many processes as cores already: OpenCV's and BLAS's own threads in each would only contend -- OpenBLAS's
    # spin while they wait, which made two workers on two cores slower than one process.
    cv2.setNumThreads(1)
    threadpool_limits(1)
    # Ctrl-C reaches the whole process group: the stage stops its workers itself (below), without a traceback
    # from each of them.
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    threading.Thread(target=_end_with, args=(stage,), daemon=True).start()


def _end_with(stage: int) -> None:
    # A stage killed outright (SIGKILL, the OOM killer, a script without a SIGTERM handler) cannot end its workers:
    # each ends itself once the stage is gone, instead of computing its queued views and then waiting forever.
    while _running(stage):
        time.sleep(ORPHAN_CHECK_S)
    os._exit(1)


def _running(pid: int) -> bool:
    """Whether process ``pid`` runs: it exists and, where /proc tells, is no zombie (killed, not yet reaped)."""
    try:
        os.kill(pid, 0)
    except (ProcessLookupError, PermissionError):  # gone (or its pid is someone else's now)
        return False
    try:
        stat = Path(f"/proc/{pid}/stat").read_text()
    except OSError:  # no /proc (macOS)
        return True
    return stat[stat.rindex(")") + 2] != "Z"  # the state follows the command's name in parentheses


@contextmanager
def view_workers(workers: int) -> Iterator[MapViews]:
    """A :data:`MapViews` over ``workers`` processes (0: :func:`usable_cores`; 1: :func:`serial`, no pool), shut
    down on leaving. The processes are started by a fork server, not forked from this process: it may hold
    threads (progress bars, PyTorch) that a fork would copy mid-lock. The fork server imports the main script, as
    Python's ``spawn`` does: a script that runs the masks with workers needs ``if __name__ == "__main__":``. When
    the stage stops (Ctrl-C, SIGTERM, an error) the workers are ended at once, not left to finish the queued
    views."""
    count = workers or usable_cores()
    if count <= 1:
        yield serial
        return
    method = "forkserver" if "forkserver" in multiprocessing.get_all_start_methods() else "spawn"  # Windows: spawn
    pool = ProcessPoolExecutor(count, mp_context=multiprocessing.get_context(method), initializer=_worker_start,
                               initargs=(os.getpid(),))

    def run(fn: Callable[..., T], tasks: Sequence[tuple[Any, ...]], done: Callable[[], None] = lambda: None
            ) -> list[T]:
        futures = [pool.submit(fn, *task) for task in tasks]
        out = []
        for future in futures:
            try:
                out.append(future.result())
            except BrokenProcessPool as error:
                raise OrcaError(f"a masks worker process ended abruptly ({error})", fix="it was most likely out of "
                                "memory: run with fewer workers (--set masks.workers=1 uses none) or a smaller "
                                "masks.work_size") from error
            done()
        return out

    try:
        yield run
    except BaseException:
        # the executor has no public way to end running tasks before Python 3.14's terminate_workers
        for process in list((getattr(pool, "_processes", None) or {}).values()):
            process.terminate()
        pool.shutdown(wait=True, cancel_futures=True)
        raise
    pool.shutdown(wait=True)
