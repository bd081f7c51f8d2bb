"""``lfdeblur batch simulate|deblur``: many light fields on dask.distributed.

Exit status: 0 when every item is done, 1 when some failed (the count is
printed, and a line per failed item), 2 on bad usage.
"""

from __future__ import annotations

import _thread
import contextlib
import logging
import shlex
import sys
import threading
from pathlib import Path

from ._cli_progress import counting_bar
from ._cli_types import seed, value_range

__all__ = ["add_batch", "run_batch", "blind_params", "weak_blur_summary", "ctrl_c_never_swallowed"]


def _common(p) -> None:
    p.add_argument("inputs", metavar="IN_GLOB",
                   help="a glob pattern of input light fields (quote it: 'scenes/*.npz'), or one file or folder")
    p.add_argument("out_dir", metavar="OUT_DIR", help="output folder: one .npz and path JSON per item, "
                   "manifest.jsonl, README.md")
    p.add_argument("--scheduler", metavar="ADDRESS",
                   help="a dask scheduler, e.g. tcp://HOST:8786 (default: a local cluster)")
    p.add_argument("--workers", type=int, metavar="N",
                   help="worker processes of the local cluster (default: one per core)")
    p.add_argument("--device", default="auto", choices=("auto", "cpu", "cuda"),
                   help="cuda: run on workers with the resource GPU=1; auto: on them if any (default auto)")
    p.add_argument("--infinity-disparity", type=float, default=None,
                   help="d_inf in px/view (simulate: default 0; deblur: default each input's own, the one its file "
                   "states, as batch simulate's outputs do, else 0)")
    p.add_argument("--seed", type=seed, default=0, help="the run's seed (default 0)")
    p.add_argument("--value-range", type=value_range, default=None, metavar="LO,HI",
                   help="the stored values that become 0 and 1 when the inputs are read, such as 0,4095 for "
                   "12-bit data in a 16-bit file, or auto (each input's own minimum and maximum)")
    p.add_argument("--overwrite", action="store_true", help="recompute every item and replace its output")


def _extent(text: str):
    """``--extent``: a size in views, or ``MIN:MAX`` to draw it from."""
    try:
        parts = [float(t) for t in text.split(":")]
    except ValueError:
        raise ValueError(f"--extent {text!r}: expected a number or MIN:MAX") from None
    if len(parts) not in (1, 2):
        raise ValueError(f"--extent {text!r}: expected a number or MIN:MAX")
    return parts[0] if len(parts) == 1 else tuple(parts)


def add_batch(sub) -> None:
    """Declare ``batch simulate`` and ``batch deblur`` on the ``lfdeblur`` subparsers ``sub``."""
    from .batch import PATH_KINDS

    batch = sub.add_parser("batch", help="many light fields on dask.distributed: simulate a dataset, deblur "
                           "a folder (resumable)")
    kinds = batch.add_subparsers(dest="batch_command", metavar="{simulate,deblur}")
    kinds.required = True
    p = kinds.add_parser("simulate", help="blur each input by random camera paths")
    _common(p)
    p.add_argument("--n-per-input", type=int, default=1, metavar="K", help="items per input (default 1)")
    p.add_argument("--path-kind", default="random", choices=PATH_KINDS, help="kind of path (default random)")
    p.add_argument("--extent", default="2",
                   help="in views, or MIN:MAX to draw it (default 2): the length of linear and arc, the side of the "
                   "box of the random control points of shake, shake6 and random")
    p.add_argument("--noise", type=float, default=0.0, help="Gaussian noise standard deviation (default 0)")
    p.add_argument("--n-times", type=int, default=32, help="exposure instants T (default 32)")
    p = kinds.add_parser("deblur", help="deblur each input blindly")
    _common(p)
    p.add_argument("--preset", default="default", help="parameter preset: default or paper (default: default)")
    p.add_argument("--params", help="a JSON file of BlindParams, nested by stage (overrides --preset)")


def blind_params(args):
    """The BlindParams of ``--params`` (a JSON file), else of ``--preset``."""
    from .blind import BlindParams

    if not args.params:
        return BlindParams.preset(args.preset)
    path = Path(args.params)
    if not path.is_file():
        raise ValueError(f"parameter file {path} {'is a folder' if path.is_dir() else 'does not exist'}")
    return BlindParams.from_json(path.read_text())


def _command(args) -> str:
    """The command that makes the same outputs (for the dataset card): data options only."""
    words = ["lfdeblur", "batch", args.batch_command, args.inputs, args.out_dir]
    if args.batch_command == "simulate":
        words += ["--n-per-input", args.n_per_input, "--path-kind", args.path_kind, "--extent", args.extent,
                  "--noise", args.noise, "--n-times", args.n_times]
    else:
        words += ["--params", args.params] if args.params else ["--preset", args.preset]
    if args.infinity_disparity is not None:
        words += ["--infinity-disparity", args.infinity_disparity]
    words += ["--seed", args.seed]
    if args.value_range is not None:
        words.append("--value-range=" + ("auto" if args.value_range == "auto" else "%r,%r" % args.value_range))
    return " ".join(shlex.quote(str(w)) for w in words)


def run_batch(args) -> int:
    """Run ``lfdeblur batch ...``; returns the exit status (0, or 1 when items failed)."""
    from ._cli_info import CLIError

    try:
        return _run(args)
    except (ImportError, RuntimeError) as exc:  # dask missing, another run in OUT_DIR
        raise CLIError(str(exc)) from None


def _run(args) -> int:
    from .batch import deblur_many, expand_inputs, simulate_dataset
    from .batch._worker_setup import fold_dask_tracebacks

    inputs = expand_inputs(args.inputs)
    n_inputs = len(inputs)
    for flag, value in (("--workers", args.workers), ("--n-per-input", getattr(args, "n_per_input", 1))):
        if value is not None and value < 1:
            raise ValueError(f"{flag} must be >= 1; got {value}")
    if args.batch_command == "simulate" and args.infinity_disparity is None:
        args.infinity_disparity = 0.0
    command = _command(args)
    if args.batch_command == "simulate":
        total = n_inputs * args.n_per_input
        run = simulate_dataset
        options = dict(n_per_input=args.n_per_input, path_kind=args.path_kind, extent=_extent(args.extent),
                       noise=args.noise, n_times=args.n_times)
    else:
        total, run, options = n_inputs, deblur_many, dict(params=blind_params(args))
    fold_dask_tracebacks()  # this process's; the embedded workers fold their own
    bar = []  # made at the first item: arguments are checked and the cluster started before

    def show(rec):
        if not bar:
            bar.append(counting_bar(total, unit="item"))
        if rec["status"] == "failed":
            bar[0].write(f"failed: {rec['input']} -> {rec['output']}: {rec['error']}", file=sys.stderr)
        bar[0].update(1)

    with ctrl_c_never_swallowed(), _dashboard_on_stderr():
        try:  # the cluster is started (or the scheduler reached) only once the arguments and folder are checked
            report = run(inputs, args.out_dir, infinity_disparity=args.infinity_disparity, seed=args.seed,
                         value_range=args.value_range, client=args.scheduler, workers=args.workers,
                         device=args.device, overwrite=args.overwrite, callback=show, command=command, **options)
        finally:
            if bar:
                bar[0].close()
    done = f"{report.n_ok} done, {report.n_skipped} already done (skipped)" + weak_blur_summary(report.records)
    if report.n_failed:
        print(f"lfdeblur batch {args.batch_command}: {report.n_failed} of {total} items failed ({done}); "
              f"see {Path(args.out_dir) / 'manifest.jsonl'}; once their errors are dealt with, rerun the same "
              "command to redo them", file=sys.stderr)
        return 1
    print(f"all {total} items in {args.out_dir} ({done})")
    return 0


@contextlib.contextmanager
def _dashboard_on_stderr():
    """Within it, the batch's log of the dask dashboard's address is printed on stderr."""
    log = logging.getLogger("napari_lfdeblur.batch")
    handler = logging.StreamHandler(sys.stderr)
    handler.setFormatter(logging.Formatter("%(message)s"))
    level = log.level
    log.addHandler(handler)
    log.setLevel(logging.INFO)
    try:
        yield
    finally:
        log.removeHandler(handler)
        log.setLevel(level)


@contextlib.contextmanager
def ctrl_c_never_swallowed():
    """Within it, a KeyboardInterrupt raised in a finalizer reaches the main thread.

    A Ctrl-C can land while the main thread runs a finalizer (a dask
    ``Future.__del__``, when a finished item's future is released): Python
    then prints "Exception ignored" with a traceback and carries on, and the
    run would go to its end. Here nothing is printed and the interrupt is
    raised again in the main thread (``_thread.interrupt_main``) 0.1 s later,
    from a timer thread, so that it arrives once the finalizer and this hook
    have returned (raised within them, it would be ignored again; should it
    land in another finalizer, the same happens again).
    """
    default = sys.unraisablehook

    def hook(unraisable):
        if isinstance(unraisable.exc_value, KeyboardInterrupt):
            timer = threading.Timer(0.1, _thread.interrupt_main)
            timer.daemon = True
            timer.start()
        else:
            default(unraisable)

    sys.unraisablehook = hook
    try:
        yield
    finally:
        sys.unraisablehook = default


def weak_blur_summary(records) -> str:
    """What the run's summary line adds about inputs with little blur found: how many were returned
    unchanged and how many restored lightly; and about those with blur found whose restoration did not
    reproduce the data, returned unchanged (empty when none)."""
    weak = [r.get("restoration", "none") for r in records if r["status"] == "ok" and r.get("blur_found") is False]
    refused = sum(r["status"] == "ok" and r.get("blur_found") is True and r.get("restoration") == "none"
                  for r in records)
    done = ""
    if weak.count("none"):
        done += f"; {weak.count('none')} with little blur found, returned unchanged (blur_found in the manifest)"
    if weak.count("light"):
        done += f"; {weak.count('light')} with little blur found, restored lightly (restoration in the manifest)"
    if refused:
        done += (f"; {refused} with blur found but a restoration that did not reproduce the data, returned "
                 "unchanged (restoration in the manifest)")
    return done
