"""A SIGTERM whose exception Python swallows (it landed while a finalizer ran) still stops the stage at its next
step: the training loop and every progress bar raise it again."""

from __future__ import annotations

import gc
import os
import signal

import pytest

from pipeline.log import progress
from pipeline.signals import Terminated, raise_if_terminated, stop_on_sigterm, stopped_by

# the finalizer's swallowed exception is what these tests make happen
pytestmark = pytest.mark.filterwarnings("ignore::pytest.PytestUnraisableExceptionWarning")


class _KilledWhileCollected:
    """Sends this process SIGTERM from its finalizer: the handler's exception is raised inside ``__del__``, where
    Python prints "Exception ignored" and drops it."""

    def __del__(self) -> None:
        os.kill(os.getpid(), signal.SIGTERM)


@pytest.fixture
def sigterm_handled():
    before = signal.getsignal(signal.SIGTERM)
    stop_on_sigterm()
    yield
    signal.signal(signal.SIGTERM, before)


def _swallow_a_sigterm() -> None:
    obj = _KilledWhileCollected()
    del obj
    gc.collect()


def test_a_sigterm_swallowed_by_a_finalizer_is_raised_at_the_next_check(sigterm_handled):
    _swallow_a_sigterm()  # no exception reaches here: the finalizer swallowed it
    with pytest.raises(Terminated):
        raise_if_terminated()
    raise_if_terminated()  # raised once: handled, it does not come back


def test_a_progress_bar_step_raises_a_swallowed_sigterm(sigterm_handled):
    with progress() as bar:
        task = bar.add_task("work", total=3)
        bar.advance(task)
        _swallow_a_sigterm()
        with pytest.raises(Terminated):
            bar.advance(task)
        bar.advance(task)
        stop_on_sigterm()  # the first SIGTERM left it ignored (one unwinding is enough)
        _swallow_a_sigterm()
        with pytest.raises(Terminated):
            bar.update(task, completed=3)
        bar.update(task, completed=3)


def test_a_handled_stop_is_not_raised_again(sigterm_handled):
    """A SIGTERM whose exception was delivered and handled (the command line reads it with ``stopped_by``) does not
    fire a second time."""
    with pytest.raises(Terminated) as stop:
        os.kill(os.getpid(), signal.SIGTERM)
        for _ in range(1000):  # the handler runs between bytecodes, at once
            pass
    assert stopped_by(stop.value) == signal.SIGTERM
    raise_if_terminated()
