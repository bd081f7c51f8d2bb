"""One long-lived thread for all of the plugin's torch work.

PyTorch's CPU kernels run in OpenMP parallel regions, and libgomp keeps a
pool of helper threads for every thread that starts one. When the pools
together hold more threads than the machine has cores, libgomp stops
spinning between parallel regions and puts its threads to sleep, so every
small operation then waits for them to wake up: small tensor operations run
several times slower, and a whole solver noticeably so
(``benchmarks/bench_widget_fullres.py``).

napari runs each job on one of Qt's pool threads, and sample data are made
in the GUI thread. The plugin instead runs every solver step, preview and
sample on the one thread of this module, so the process keeps a single
pool.
"""

from __future__ import annotations

import threading
from concurrent.futures import ThreadPoolExecutor

from ..progress import cancellable

__all__ = ["call", "iterate"]

_lock = threading.Lock()
_executor: ThreadPoolExecutor | None = None


def _thread() -> ThreadPoolExecutor:
    global _executor
    with _lock:
        if _executor is None:
            _executor = ThreadPoolExecutor(max_workers=1, thread_name_prefix="napari-lfdeblur-torch")
        return _executor


def call(fn, *args, **kwargs):
    """``fn(*args, **kwargs)`` run on the torch thread; its result, or its exception re-raised here.

    Must not be called from the torch thread itself (it would wait for itself).
    """
    return _thread().submit(fn, *args, **kwargs).result()


def _step(gen, cancel):
    if cancel is None:
        return next(gen)
    with cancellable(cancel):
        return next(gen)


def iterate(gen, cancel: threading.Event | None = None):
    """A generator that steps ``gen`` on the torch thread and yields its records here.

    It returns ``gen``'s result; closing it (a cancelled napari worker) closes
    ``gen`` on the torch thread. With ``cancel``, each step runs inside
    :func:`napari_lfdeblur.progress.cancellable`: once the event is set, the
    step stops at the solver's next cancellation point and
    :class:`~napari_lfdeblur.progress.Cancelled` is raised here.
    """
    try:
        while True:
            try:
                record = call(_step, gen, cancel)
            except StopIteration as stop:
                return stop.value
            yield record
    finally:
        call(gen.close)
