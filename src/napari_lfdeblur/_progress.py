"""The progress record every iterative solver yields.

Solvers are generators (``iter_deconvolve``, ``iter_blind_deblur``): they
yield :class:`Progress` records and *return* their result, so a script gets
it from ``StopIteration.value`` (or simply calls the non-generator form), and
napari's ``thread_worker`` emits it through its ``returned`` signal. Closing
the generator (``gen.close()``, or quitting the worker) stops the work at the
next ``yield``.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

__all__ = ["Progress", "run_to_completion"]


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
    control_points : ndarray or None, shape (n, 3)
        Current path estimate, when the solver estimates one.
    preview : ndarray or None
        A current light-field estimate, (V, U, Y, X[, C]) float32; sent only
        now and then, since it costs a copy.
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
    """
    while True:
        try:
            record = next(gen)
        except StopIteration as stop:
            return stop.value
        if callback is not None:
            callback(record)
