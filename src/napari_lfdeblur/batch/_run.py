"""The client side of a batch: the cluster, the plan (what to skip), the submission loop."""

from __future__ import annotations

import datetime
import glob
import json
import logging
import os
import shutil
import warnings
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path

from ._items import item_metadata, item_seed, run_item
from ._manifest import CARD, append_record, check_card, open_manifest, read_manifest, write_card

__all__ = ["BatchReport", "connect", "expand_inputs", "gpu_workers", "run_batch"]

_INSTALL = 'the batch API needs dask.distributed: pip install "napari-lfdeblur[batch]"'
_MAIN_GUARD = ("in a script, call simulate_dataset and deblur_many under `if __name__ == '__main__':`: each worker "
               "process of the embedded cluster starts by importing the script, which must not start a batch again")

#: glibc's mmap threshold for the worker processes of the embedded cluster, in bytes. dask's nanny
#: sets ``MALLOC_TRIM_THRESHOLD_`` to 64 KiB before it spawns a worker, and any explicit malloc
#: setting freezes glibc's dynamic mmap threshold at 128 KiB: every array over that size is then a
#: fresh ``mmap`` whose pages fault in on first touch, on every item. 32 MiB is the ceiling that
#: glibc's dynamic threshold reaches in a plain process, so light fields up to that size reuse freed
#: memory there too.
WORKER_MMAP_THRESHOLD = 32 * 2**20
#: glibc's trim threshold for the same workers: twice the mmap threshold, as glibc's dynamic rule
#: sets it. dask's 64 KiB returns the top of the heap to the system after every item, and the next
#: item faults its pages in again.
WORKER_TRIM_THRESHOLD = 2 * WORKER_MMAP_THRESHOLD
_ENV_KEY = "distributed.nanny.pre-spawn-environ."
_WORKER_SETUP = "napari_lfdeblur.batch._worker_setup"  # a dask preload module

#: dask settings of the embedded cluster. Its client, scheduler and nannies share the machine with
#: the workers, so their timers take CPU from the items: the statistical profiler wakes every 10 ms
#: and takes the GIL from the task; the event-loop latency probe (``tick``, 20 ms), the nannies'
#: memory monitor (100 ms) and the system monitor (500 ms) cost together about 0.1 s of CPU per
#: second of an idle 2-worker cluster. They are slowed here to about a fifth of that; the
#: memory limit is still enforced, at 0.5 s.
EMBEDDED_CLUSTER_CONFIG = {
    _ENV_KEY + "MALLOC_MMAP_THRESHOLD_": str(WORKER_MMAP_THRESHOLD),
    _ENV_KEY + "MALLOC_TRIM_THRESHOLD_": str(WORKER_TRIM_THRESHOLD),
    "distributed.worker.profile.enabled": False,
    "distributed.admin.tick.interval": "500ms",
    "distributed.worker.memory.monitor-interval": "500ms",
    "distributed.admin.system-monitor.interval": "2s",
}


@dataclass
class BatchReport:
    """What a batch run did.

    Attributes
    ----------
    out_dir : Path
        The output folder (holds ``manifest.jsonl`` and ``README.md``).
    records : list of dict
        The manifest record of every item of this run, in input order; skipped
        items carry their earlier record with ``status='skipped'``.
    """

    out_dir: Path
    records: list = field(default_factory=list)

    def count(self, status: str) -> int:
        """How many items ended with ``status`` (``'ok'``, ``'failed'`` or ``'skipped'``)."""
        return sum(r["status"] == status for r in self.records)

    @property
    def n_ok(self) -> int:
        return self.count("ok")

    @property
    def n_failed(self) -> int:
        return self.count("failed")

    @property
    def n_skipped(self) -> int:
        return self.count("skipped")

    @property
    def failed(self) -> list:
        """The records of the failed items."""
        return [r for r in self.records if r["status"] == "failed"]


def _starting_process() -> bool:
    """Whether this runs while a spawned process imports the parent's main script.

    A process started by ``multiprocessing``'s spawn (as dask's nannies start
    their workers) first runs the parent's script as ``__mp_main__``
    (``multiprocessing.spawn.prepare``), before it runs any task.
    """
    import sys

    frame = sys._getframe(1)
    while frame is not None:
        code = frame.f_code
        if code.co_name == "prepare" and code.co_filename.endswith(os.path.join("multiprocessing", "spawn.py")):
            return True
        frame = frame.f_back
    return False


def _distributed():
    try:
        import distributed
    except ImportError:
        raise ImportError(_INSTALL) from None
    return distributed


@contextmanager
def connect(client=None, *, workers: int | None = None, device: str = "auto"):
    """A dask ``Client``: the one given, one connected to a scheduler address, or an embedded cluster.

    Parameters
    ----------
    client : distributed.Client, str or None
        ``None`` starts a ``LocalCluster`` of single-threaded worker processes,
        ``workers`` of them (default: one per core; with ``device='cuda'``, one
        with the resource ``GPU=1``); a string is a scheduler address
        (``tcp://host:8786``); a client is used as it is. The embedded
        cluster's workers start with glibc's mmap and trim thresholds at
        :data:`WORKER_MMAP_THRESHOLD` and :data:`WORKER_TRIM_THRESHOLD`, and the cluster with dask's timers
        slowed (:data:`EMBEDDED_CLUSTER_CONFIG`: no statistical profiler;
        docs/batch.md says why; start a cluster of your own for the
        dashboard's profile). As in dask, ``MALLOC_MMAP_THRESHOLD_`` and
        ``MALLOC_TRIM_THRESHOLD_`` already in this process's environment
        take precedence; a local cluster started earlier in the process
        leaves dask's own values there.
    workers : int, optional
        Worker processes of the embedded cluster.
    device : {'auto', 'cpu', 'cuda'}
        Where the items will run (decides the embedded cluster's resources).

    Yields
    ------
    distributed.Client
        Closed on exit when this function made it (with its cluster); its
        dashboard's address is then logged (logger ``napari_lfdeblur.batch``,
        INFO), which the command line prints.
    """
    distributed = _distributed()
    if isinstance(client, distributed.Client):
        yield client
        return
    if isinstance(client, (str, os.PathLike)):
        with distributed.Client(str(client)) as c:
            _announce(c)
            yield c
        return
    _check_client(client, workers, device)
    import torch

    gpu = device == "cuda" or (device == "auto" and torch.cuda.is_available())
    n = workers or (1 if gpu else os.cpu_count() or 1)
    import dask

    try:
        with dask.config.set(EMBEDDED_CLUSTER_CONFIG):
            cluster = distributed.LocalCluster(n_workers=n, threads_per_worker=1, processes=True,
                                               resources={"GPU": 1} if gpu else None, dashboard_address=":0",
                                               env={"OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1"},
                                               preload=[_WORKER_SETUP])
    except RuntimeError as exc:  # e.g. "Nanny failed to start worker process"
        raise RuntimeError(f"the embedded cluster's workers did not start ({exc}); {_MAIN_GUARD}") from exc
    with cluster, distributed.Client(cluster) as c:
        _announce(c)
        yield c


def _announce(client) -> None:
    """Log (``napari_lfdeblur.batch``, INFO) where the dashboard of a cluster this package connected to is."""
    logging.getLogger("napari_lfdeblur.batch").info("dask dashboard: %s", client.dashboard_link)


def _check_client(client, workers, device) -> None:
    """The arguments of :func:`connect` checked before anything starts; for the embedded cluster (``client``
    None) with ``device='cuda'``, that this machine has a CUDA GPU."""
    if client is not None and not isinstance(client, (str, os.PathLike, _distributed().Client)):
        raise TypeError(f"client must be a distributed.Client, a scheduler address or None; got {client!r}")
    if workers is not None and (isinstance(workers, bool) or not isinstance(workers, int) or workers < 1):
        raise ValueError(f"workers must be an integer >= 1; got {workers!r}")
    if device not in ("auto", "cpu", "cuda"):
        raise ValueError(f"device must be 'auto', 'cpu' or 'cuda'; got {device!r}")
    if device == "cuda" and client is None:  # the embedded cluster runs here: no GPU, no run
        from ..devices import select_device

        select_device(device)


def gpu_workers(client) -> int:
    """How many workers of ``client``'s cluster offer the resource ``GPU``."""
    workers = client.scheduler_info().get("workers", {})
    return sum(1 for w in workers.values() if w.get("resources", {}).get("GPU", 0) >= 1)


def expand_inputs(inputs) -> list[Path]:
    """The input files or folders: a glob pattern, one path, or a sequence of paths (order kept).

    A pattern keeps the matches whose kind the reader knows
    (:func:`~napari_lfdeblur.io.detect_layout`: a light-field suffix or a
    folder of views), so that ``'out/*'`` over a batch's output folder takes
    its light fields, not its path files, manifest and README; the others are
    named in a warning. Paths given one by one must exist and be of a kind
    the reader knows (a folder holds views; for the files in a folder pass
    a pattern); one whose content cannot be read becomes a failed item.
    """
    if isinstance(inputs, (str, os.PathLike)):
        text = str(inputs)
        if glob.has_magic(text):
            found = [Path(p) for p in sorted(glob.glob(text, recursive=True))]
            kept = [p for p in found if _lightfield_kind(p)]
            if not kept:
                raise ValueError(f"no light field matches {text!r}" + (
                    f" (it matches {len(found)} other file(s), such as {found[0].name})" if found else ""))
            if len(kept) < len(found):
                others = [p.name for p in found if p not in kept]
                warnings.warn(f"{text!r}: skipped {len(others)} match(es) that are not light fields: "
                              f"{', '.join(others[:5])}{', ...' if len(others) > 5 else ''}", stacklevel=2)
            return kept
        inputs = [inputs]
    try:
        paths = [Path(p) for p in inputs]
    except TypeError:
        raise TypeError(f"inputs must be a glob pattern, a path or a sequence of paths; got {inputs!r}") from None
    if not paths:
        raise ValueError("no inputs")
    names = {}
    for p in paths:
        if not p.exists():
            raise FileNotFoundError(f"input {p} does not exist")
        if not _lightfield_kind(p):
            hint = f"; for the files in it pass a pattern such as '{p / '*'}'" if p.is_dir() else ""
            raise ValueError(f"input {p} is not a light field the reader knows{hint}")
        if p.name in names:
            raise ValueError(f"inputs {names[p.name]} and {p} share the name {p.name!r}; their outputs and "
                             "seeds would collide: rename one")
        names[p.name] = p
    return paths


def _lightfield_kind(path: Path) -> bool:
    """Whether the reader knows the kind of ``path`` (by its name or, for a folder, its files' names)."""
    from ..io import LightFieldError, detect_layout

    try:
        detect_layout(path)
    except (LightFieldError, OSError):
        return False
    return True


def _is_done(spec: dict, last: dict | None) -> bool:
    """Whether the output exists and matches its manifest record (status ok, same item, same size)."""
    if last is None or last.get("status") != "ok" or spec["overwrite"]:
        return False
    out = Path(spec["output"])
    same = all(last.get(k) == v for k, v in item_metadata(spec).items())
    return (same and out.is_file()
            and out.stat().st_size == last.get("size") and Path(spec["path_json"]).is_file())


def _sweep_temporaries(out_dir: Path, specs) -> None:
    """Remove temporary files left by killed writers of these items (no task of theirs is running)."""
    for spec in specs:
        for name in (Path(spec["output"]).name, Path(spec["path_json"]).name):
            for tmp in out_dir.glob(f".{glob.escape(name)}.tmp*"):
                if tmp.is_file():
                    tmp.unlink(missing_ok=True)


def _record(spec: dict, result: dict) -> dict:
    out_dir = Path(spec["output"]).parent
    return {
        "kind": spec["kind"], "input": spec["input"], "name": spec["name"], "index": spec["index"],
        "output": Path(spec["output"]).name, "path": Path(spec["path_json"]).relative_to(out_dir).as_posix(),
        "parameters": spec["parameters"], "seed": spec["seed"], "item_seed": spec["item_seed"],
        "version": spec["version"], "finished": datetime.datetime.now(datetime.timezone.utc).isoformat(),
        **result,
    }


def _failure(exc) -> dict:
    return {"status": "failed", "error": f"{type(exc).__name__}: {exc}", "size": None, "shape": None,
            "recovered": False, "time": None, "warnings": []}


def _collect(client, todo, resources, manifest, callback, records):
    """Submit the items, append each finished one to the manifest, call ``callback``."""
    distributed = _distributed()
    futures = {}
    for i, spec in todo:
        key = f"lfdeblur-{spec['kind']}-{spec['name']}-{spec['index']}-{os.urandom(4).hex()}"
        futures[client.submit(run_item, spec, key=key, pure=False, resources=resources)] = (i, spec)
    try:
        for fut in distributed.as_completed(list(futures)):
            i, spec = futures.pop(fut)
            try:
                result = fut.result()
            except Exception as exc:  # a killed worker, a cancelled task: the item failed, the run goes on
                result = _failure(exc)
            rec = _record(spec, result)
            append_record(manifest, rec)
            records[i] = rec
            if callback is not None:
                callback(rec)
    finally:
        if futures:
            client.cancel(list(futures))


def run_batch(specs: list, out_dir: Path, *, client, workers, device, card: dict, callback=None) -> BatchReport:
    """Run the items ``specs`` (dicts, see :func:`~._items.run_item`) into ``out_dir``.

    Raises RuntimeError, before touching ``out_dir``, where it runs as a
    script imported by a worker process being started (the script calls it
    unguarded by ``if __name__ == '__main__':``).
    """
    if _starting_process():
        raise RuntimeError(_MAIN_GUARD)
    _check_client(client, workers, device)
    outputs = [Path(s["output"]).name for s in specs]
    if len(set(outputs)) < len(outputs):
        dup = sorted({o for o in outputs if outputs.count(o) > 1})
        raise ValueError(f"several inputs would write {', '.join(dup[:3])}: rename them")
    clash = [s["input"] for s in specs if Path(s["input"]).resolve() == Path(s["output"]).resolve()]
    if clash:
        raise ValueError(f"the output of {clash[0]} would replace it: choose another output folder")
    from ..io._write import path_json_beside

    beside = [(s["input"], path_json_beside(s["input"])) for s in specs]  # an input's own path file
    clash = [(i, b) for (i, b), s in zip(beside, specs)
             if b.is_file() and b.resolve() == Path(s["path_json"]).resolve()]
    if clash:
        raise ValueError(f"the output of {clash[0][0]} would replace its path file {clash[0][1]}: choose another "
                         "output folder")
    if out_dir.exists() and not out_dir.is_dir():
        raise NotADirectoryError(f"{out_dir} is a file; a batch writes into a folder")
    created = not out_dir.exists()
    out_dir.mkdir(parents=True, exist_ok=True)
    try:
        return _run_in(specs, out_dir, client=client, workers=workers, device=device, card=card, callback=callback)
    except BaseException:
        if created:
            _remove_if_unused(out_dir)
        raise


def _remove_if_unused(out_dir: Path) -> None:
    """Remove a folder this run made when the run failed before writing anything but its card and an empty
    manifest (a cluster that did not start, a scheduler out of reach)."""
    from ._manifest import MANIFEST

    entries = {p.name: p for p in out_dir.iterdir()}
    if set(entries) <= {CARD, MANIFEST} and (MANIFEST not in entries or entries[MANIFEST].stat().st_size == 0):
        shutil.rmtree(out_dir, ignore_errors=True)


def _run_in(specs, out_dir: Path, *, client, workers, device, card, callback) -> BatchReport:
    """:func:`run_batch` once ``out_dir`` exists."""
    check_card(out_dir)
    with open_manifest(out_dir) as manifest:
        last = read_manifest(out_dir)
        records, todo = [None] * len(specs), []
        for i, spec in enumerate(specs):
            prev = last.get(Path(spec["output"]).name)
            spec["recorded"] = prev is not None and prev.get("status") == "ok"  # an output of ours was there
            if _is_done(spec, prev):
                records[i] = {**prev, "status": "skipped"}
                if callback is not None:
                    callback(records[i])
            else:
                todo.append((i, spec))
        previous = (out_dir / CARD).read_text(encoding="utf-8") if (out_dir / CARD).is_file() else None
        write_card(out_dir, **card)
        _sweep_temporaries(out_dir, [s for _, s in todo])
        if todo:
            try:
                with connect(client, workers=workers, device=device) as c:
                    use_gpu = _use_gpu(c, device)
                    for _, spec in todo:
                        spec["device"] = "cuda" if use_gpu else "cpu"
                    _collect(c, todo, {"GPU": 1} if use_gpu else None, manifest, callback, records)
            except BaseException:
                if all(records[i] is None for i, _ in todo):  # refused, or stopped before any item: the card stays
                    if previous is None:
                        (out_dir / CARD).unlink(missing_ok=True)
                    else:
                        (out_dir / CARD).write_text(previous, encoding="utf-8")
                raise
            finally:  # after an embedded cluster has closed, its workers write nothing more
                _sweep_temporaries(out_dir, [s for _, s in todo])
        report = BatchReport(out_dir=out_dir, records=records)
        if previous is not None and report.n_failed and not report.n_ok + report.n_skipped:
            (out_dir / CARD).write_text(previous, encoding="utf-8")  # nothing of this run stands: the card stays
        else:
            write_card(out_dir, **card, counts={"ok": report.n_ok, "skipped": report.n_skipped,
                                                "failed": report.n_failed})
    return report


def _use_gpu(client, device: str) -> bool:
    """Whether the items run on GPU workers: ``'cuda'`` requires them, ``'auto'`` uses them when present."""
    if device == "cpu":
        return False
    n = gpu_workers(client)
    if device == "cuda" and n == 0:
        raise ValueError("device='cuda' but no worker offers the resource GPU: start workers with "
                         "`dask worker SCHEDULER --resources GPU=1`")
    return n > 0


def make_spec(kind, inp: Path, index: int, output: Path, *, parameters: dict, seed: int, overwrite: bool,
              version: str) -> dict:
    """The small dict that describes one item to its task."""
    from ..io._write import sidecar_path_json

    parameters = json.loads(json.dumps(parameters))  # as the manifest holds them: lists, not tuples
    return {"kind": kind, "input": str(inp.resolve()), "name": inp.name, "index": index,
            "output": str(output), "path_json": str(sidecar_path_json(output, "npz")),
            "parameters": parameters, "seed": seed, "item_seed": item_seed(seed, inp.name, index),
            "overwrite": bool(overwrite), "version": version, "device": "cpu"}
