"""Set-up of the embedded cluster's worker processes: a dask preload module."""

from __future__ import annotations

import signal
import threading


def dask_setup(worker) -> None:
    """Ignore SIGINT in the worker process.

    A Ctrl-C in a terminal goes to the whole process group: the workers of an
    embedded cluster would each stop with a traceback. Ignored there, it
    reaches only the client, which cancels the items and closes the cluster.
    """
    if threading.current_thread() is threading.main_thread():
        signal.signal(signal.SIGINT, signal.SIG_IGN)
