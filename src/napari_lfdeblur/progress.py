"""The progress record every iterative solver yields.

Solvers are generators (``iter_deconvolve``, ``iter_blind_deblur``): they
yield :class:`Progress` records and *return* their result, so a script gets
it from ``StopIteration.value`` (or simply calls the non-generator form), and
napari's ``thread_worker`` emits it through its ``returned`` signal. Closing
the generator (``gen.close()``, or quitting the worker) stops the work at the
next ``yield``. A caller that runs a solver in another thread can also stop
it *between* two records: inside :func:`cancellable` with an event, the
solvers' long iterations check the event at their cancellation points
(:func:`check_cancelled`) and raise :class:`Cancelled` once it is set.

How often a caller materialises the current light-field estimate is the
caller's choice, not the solver's: a record carries a cheap ``estimate``
callable, and :func:`with_previews` turns it into a ``preview`` array every
so many records (in the thread that runs the solver).
"""

from __future__ import annotations

import contextlib
import math
import threading
import time
from dataclasses import dataclass, field
from typing import Any, Callable

import numpy as np

__all__ = ["Cancelled", "Progress", "cancellable", "check_cancelled", "run_to_completion", "with_previews"]


@dataclass
class Progress:
    """One progress report of an iterative solver.

    Attributes
    ----------
    stage : str
        Name of the current stage (e.g. ``'path'``, ``'tv'``, ``'wiener'``).
    iteration : int
        Iterations done in this stage (1-based).
    n_iterations : int
        Iterations planned for this stage (an upper bound with early stopping).
    loss : float
        Current objective value (NaN when the stage has none).
    control_points : ndarray or None, shape (n, 3) or (n, 6)
        Current path estimate, when the solver estimates one (``(n, 6)``
        with rotation).
    preview : ndarray or None
        A current light-field estimate, (V, U, Y, X[, C]) float32, when the
        caller asked for one (see :func:`with_previews`).
    estimate : callable or None
        ``estimate()`` returns the current light-field estimate,
        (V, U, Y, X[, C]) float32 (a new array). It is valid only until the
        generator is resumed, so call it before asking for the next record.
    stage_index, n_stages : int
        Position of this stage among all stages (0-based) and their count,
        for an overall progress bar.
    info : dict
        Anything else worth showing (step sizes, epsilon, ...).
    """

    stage: str
    iteration: int
    n_iterations: int
    loss: float = float("nan")
    control_points: np.ndarray | None = None
    preview: np.ndarray | None = None
    estimate: Callable[[], np.ndarray] | None = field(default=None, repr=False)
    stage_index: int = 0
    n_stages: int = 1
    info: dict[str, Any] = field(default_factory=dict)

    @property
    def fraction(self) -> float:
        """Overall fraction done, in [0, 1]."""
        within = self.iteration / max(1, self.n_iterations)
        return min(1.0, (self.stage_index + min(1.0, within)) / max(1, self.n_stages))


def run_to_completion(gen, callback=None):
    """Drive a solver generator to its end and return its result.

    ``callback(progress)`` is called on every record when given.

    Raises
    ------
    TypeError
        If ``callback`` is given but not callable (before any work).
    """
    if callback is not None and not callable(callback):
        gen.close()
        raise TypeError(f"callback must be a function of a progress record; got {callback!r}")
    while True:
        try:
            record = next(gen)
        except StopIteration as stop:
            return stop.value
        if callback is not None:
            callback(record)


def with_previews(gen, every: int, *, share: float = 0.0, clock=time.perf_counter):
    """Wrap a solver generator so that every ``every``-th record carries a preview.

    Counting only the records that carry an ``estimate``, the wrapper calls
    ``record.estimate()`` on the ``every``-th, ``2 every``-th, ... of them and
    stores the array in ``record.preview``, in the thread that iterates the
    wrapper (a napari widget's worker thread, not the GUI thread); other
    records pass through unchanged. It returns the wrapped generator's
    result, and closing it closes ``gen``.

    With ``share > 0`` the previews are also spaced by their own cost: after
    a preview that took ``c`` seconds, the next one comes no sooner than
    ``share * c`` seconds later (the count goes on meanwhile), so previews
    take at most about ``1 / (1 + share)`` of the run, whatever the light
    field's size.

    Parameters
    ----------
    gen : generator of Progress
        A solver generator such as ``iter_deconvolve(...)``.
    every : int
        Records between previews (>= 0; 0: never).
    share : float, default 0.0
        Least time between previews, in units of the last preview's cost
        (>= 0; 0: by count only).
    clock : callable, default time.perf_counter
        Seconds, for the spacing (a parameter for tests).

    Raises
    ------
    ValueError
        If ``every`` or ``share`` is negative.
    TypeError
        If ``every`` is not an integer.
    """
    if isinstance(every, bool) or not isinstance(every, (int, np.integer)):
        raise TypeError(f"every must be an integer; got {type(every).__name__}")
    if every < 0:
        raise ValueError(f"every must be >= 0; got {every}")
    if not share >= 0:
        raise ValueError(f"share must be >= 0; got {share}")
    return _with_previews(gen, int(every), float(share), clock)


def _with_previews(gen, every, share, clock):
    count = 0
    not_before = -math.inf
    try:
        while True:
            try:
                record = next(gen)
            except StopIteration as stop:
                return stop.value
            if every and record.estimate is not None and record.preview is None:
                count += 1
                if count >= every and clock() >= not_before:
                    start = clock()
                    record.preview = record.estimate()
                    end = clock()
                    not_before = end + share * (end - start)
                    count = 0
            yield record
    finally:
        gen.close()


class Cancelled(Exception):
    """Raised at a cancellation point of a solver whose run was cancelled (see :func:`cancellable`)."""


_cancel = threading.local()


@contextlib.contextmanager
def cancellable(event: threading.Event):
    """Within this context, :func:`check_cancelled` in this thread raises :class:`Cancelled` once ``event`` is set.

    A solver generator runs in the thread that resumes it, so wrap each
    ``next()`` that should be interruptible. Contexts nest; the innermost
    event is the one checked. Outside any context the checks do nothing.

    Examples
    --------
    >>> import threading
    >>> stop = threading.Event()
    >>> with cancellable(stop):
    ...     check_cancelled()  # not set: nothing happens
    ...     stop.set()
    ...     try:
    ...         check_cancelled()
    ...     except Cancelled:
    ...         print("cancelled")
    cancelled
    """
    outer = getattr(_cancel, "event", None)
    _cancel.event = event
    try:
        yield event
    finally:
        _cancel.event = outer


def check_cancelled() -> None:
    """A cancellation point: raise :class:`Cancelled` if this thread's :func:`cancellable` event is set.

    Solvers call it inside iterations that take long between two progress
    records (the TV solver: after each blur evaluation and each inner
    iteration of its proximal map), so that a cancelled run stops within a
    fraction of an iteration.
    """
    event = getattr(_cancel, "event", None)
    if event is not None and event.is_set():
        raise Cancelled("cancelled")
