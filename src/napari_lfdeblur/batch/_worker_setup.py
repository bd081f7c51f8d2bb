"""Set-up of the embedded cluster's worker processes: a dask preload module."""

from __future__ import annotations

import logging
import signal
import threading


class OneLineTracebacks(logging.Filter):
    """Fold a log record's traceback into one line: ``message ExcType: text``."""

    def filter(self, record: logging.LogRecord) -> bool:
        if record.exc_info and record.exc_info[1] is not None:
            exc = record.exc_info[1]
            record.msg = f"{record.getMessage()} {type(exc).__name__}: {exc}".strip()
            record.args, record.exc_info, record.exc_text = None, None, None
        return True


class CancelledRunNoise(logging.Filter):
    """Drop what dask logs as a cancelled run's cluster closes: each cancelled task's ``CancelledError`` and
    the nanny's "still alive ..., killing" for a worker busy with one (the run's own line says it stopped)."""

    NOISE = ("ended with CancelledError", "Worker process still alive after")

    def filter(self, record: logging.LogRecord) -> bool:
        return not any(n in record.getMessage() for n in self.NOISE)


def fold_dask_tracebacks() -> None:
    """Fold the tracebacks that dask logs in this process (a lost scheduler, a killed worker) into one line,
    and leave out the lines a cancelled run's shutdown logs.

    Adds :class:`OneLineTracebacks` and :class:`CancelledRunNoise` to the
    handlers of the ``distributed`` logger (once); does nothing when
    dask.distributed is not installed.
    """
    try:
        import distributed  # noqa: F401  (its logging set-up gives the handlers to filter)
    except ImportError:
        return
    for h in logging.getLogger("distributed").handlers:
        for kind in (OneLineTracebacks, CancelledRunNoise):
            if not any(isinstance(f, kind) for f in h.filters):
                h.addFilter(kind())


def dask_setup(worker) -> None:
    """Ignore SIGINT in the worker process and fold its dask tracebacks.

    A Ctrl-C in a terminal goes to the whole process group: the workers of an
    embedded cluster would each stop with a traceback. Ignored there, it
    reaches only the client, which cancels the items and closes the cluster.
    While it closes, a worker can still log a lost connection to the
    scheduler: :func:`fold_dask_tracebacks` writes that on one line. An
    item's own error goes back to the client whole.
    """
    if threading.current_thread() is threading.main_thread():
        signal.signal(signal.SIGINT, signal.SIG_IGN)
    fold_dask_tracebacks()
