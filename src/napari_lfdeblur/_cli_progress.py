"""Progress of the ``lfdeblur`` commands on stderr: a bar on a terminal, a line per stage in a log."""

from __future__ import annotations

import sys
import time

__all__ = ["StageProgress", "counting_bar"]


def counting_bar(total: int, stream=None, **options):
    """A tqdm bar on ``stream`` (stderr by default) for a count of steps of a few seconds or more each (demo
    samples, batch items)."""
    from tqdm.auto import tqdm

    return tqdm(total=total, file=stream or sys.stderr, dynamic_ncols=True, **options)


class StageProgress:
    """Shows a solver's progress records on ``stream`` (stderr by default).

    On a terminal: a tqdm bar, redrawn when the stage changes and otherwise
    at most every ``interval`` seconds (a solver reports hundreds of times a
    second). Elsewhere (a log file, a pipe): one line each time the stage
    changes, ``lfdeblur COMMAND: STAGE (ELAPSED s)``, and no bar.

    Parameters
    ----------
    command : str
        The subcommand, which starts each line of a log.
    total : int
        The bar's length.
    stream : file-like, optional
        Where to write; ``sys.stderr`` when None.
    interval : float
        Seconds between two redraws of the bar within one stage.
    **bar_options
        Passed to ``tqdm`` (``desc``, ``unit``, ``bar_format``, ...).
    """

    def __init__(self, command: str, total: int, *, stream=None, interval: float = 0.1, **bar_options):
        self.command, self.stream, self.interval = command, stream or sys.stderr, interval
        self.start, self.drawn, self.stage = time.perf_counter(), -float("inf"), None
        self.bar = None
        if getattr(self.stream, "isatty", lambda: False)():
            self.bar = counting_bar(total, self.stream, **bar_options)

    def show(self, stage: str, n: int, *, total: int | None = None, description: str | None = None,
             postfix: str | None = None, bar_format: str | None = None):
        """Advance to ``n`` (of ``total``, when given) in ``stage``; the bar shows ``description``
        (default: the stage) and ``postfix``."""
        now, new_stage = time.perf_counter(), stage != self.stage
        self.stage = stage
        if self.bar is None:
            if new_stage:
                print(f"lfdeblur {self.command}: {stage} ({now - self.start:.1f} s)", file=self.stream, flush=True)
            return
        bar = self.bar
        if total is not None:
            bar.total = total
        bar.n = n
        if bar_format is not None:
            bar.bar_format = bar_format
        bar.set_description(stage if description is None else description, refresh=False)
        if postfix is not None:
            bar.set_postfix_str(postfix, refresh=False)
        if new_stage or now - self.drawn >= self.interval:
            bar.refresh()
            self.drawn = now

    def finish(self):
        """Fill the bar (stages a run skipped leave no gap) and close it."""
        if self.bar is not None:
            self.bar.n = self.bar.total
            self.bar.refresh()
        self.close()

    def close(self):
        """Close the bar (its last state stays on the terminal)."""
        if self.bar is not None:
            self.bar.close()
