"""The solver runner shared by the dock widgets.

:class:`SolverWidget` is a magicgui :class:`~magicgui.widgets.Container`: a
parameter form (``self.form``, whose first field is the input layer), Run /
Cancel buttons and a :class:`ProgressPanel`. *Run* reads the form, builds
the core's generator and runs it in a napari ``thread_worker``, wrapped in
:func:`napari_lfdeblur.progress.with_previews` at the widget's preview
cadence, spaced by their cost (:data:`PREVIEW_SHARE`; previews are computed
in the worker thread). Each progress
record updates the progress bar (stage, iteration, loss, time left); the
returned result becomes layers; an exception raised by the core becomes an
error notification. *Cancel* quits the worker and sets the run's
cancellation event: the solver stops at its next cancellation point
(:func:`napari_lfdeblur.progress.check_cancelled`, inside long iterations) or
at its next ``yield``, whichever comes first, and nothing is added.
"""

from __future__ import annotations

import logging
import threading
import time
import traceback

import numpy as np
from magicgui.widgets import Container, Label, ProgressBar, PushButton
from napari.qt.threading import thread_worker

from ..._lightfield import restore_warnings, warnings_state
from ...progress import Cancelled, with_previews
from .._torch_thread import iterate
from ..layers import LayerError, add_layer, lightfield_from_layer
from ._controls import LayerChoice, is_lightfield, notify_error, notify_info, notify_warning, placed

log = logging.getLogger(__name__)

#: a light-field preview that took ``c`` seconds to compute is followed by at least ``PREVIEW_SHARE * c``
#: seconds without one: previews then cost the run at most about 5 %, however large the light field
PREVIEW_SHARE = 20.0

__all__ = ["PREVIEW_SHARE", "ProgressPanel", "SolverWidget", "format_seconds"]

#: the widgets' runs going on, and the warnings machinery as it was before the first of them. Each superqt
#: worker swaps it process-wide while it runs and puts back what it found, so runs that overlap would leave a
#: finished worker's in place (every later warning sent to it, none shown); the last run to end
#: puts back what the first found.
_WARNINGS = {"runs": 0, "saved": None}


def _run_starts() -> None:
    if _WARNINGS["runs"] == 0:
        _WARNINGS["saved"] = warnings_state()
    _WARNINGS["runs"] += 1


def _run_ends() -> None:
    _WARNINGS["runs"] = max(0, _WARNINGS["runs"] - 1)
    if _WARNINGS["runs"] == 0 and _WARNINGS["saved"] is not None:
        restore_warnings(_WARNINGS["saved"])
        _WARNINGS["saved"] = None


def format_seconds(seconds: float) -> str:
    """``'12 s'``, ``'3 min 05 s'`` or ``'1 h 02 min'``."""
    seconds = max(0.0, float(seconds))
    if seconds < 60:
        return f"{seconds:.0f} s"
    if seconds < 3600:
        return f"{int(seconds // 60)} min {int(seconds % 60):02d} s"
    return f"{int(seconds // 3600)} h {int(seconds % 3600 // 60):02d} min"


class ProgressPanel(Container):
    """A progress bar and a status line: stage, iteration, loss and the time left."""

    def __init__(self, name: str = "progress_panel"):
        self.bar = ProgressBar(name="bar", min=0, max=1000, value=0)
        self.status = Label(name="status", value="idle")
        super().__init__(name=name, widgets=[self.bar, self.status], labels=False)
        from qtpy.QtWidgets import QSizePolicy

        self.status.native.setWordWrap(True)
        self.status.native.setSizePolicy(QSizePolicy.Policy.Expanding, QSizePolicy.Policy.Preferred)
        self.status.native.setMinimumHeight(2 * self.status.native.fontMetrics().lineSpacing() + 4)
        self.margins = (0, 0, 0, 0)
        self._t0 = None
        self.eta_seconds = None

    def _elapsed(self) -> float:
        return time.perf_counter() - (self._t0 or time.perf_counter())

    def start(self, text: str = "starting...") -> None:
        """Reset the bar and the clock."""
        self._t0 = time.perf_counter()
        self.eta_seconds = None
        self.bar.value = 0
        self.status.value = text

    def update_progress(self, progress) -> None:
        """Show a :class:`napari_lfdeblur.progress.Progress` record."""
        frac = float(getattr(progress, "fraction", 0.0))
        self.bar.value = int(round(1000 * frac))
        elapsed = self._elapsed()
        decrease = (getattr(progress, "info", None) or {}).get("relative_decrease")
        if decrease is not None:  # a solve that stops once its objective settles, mostly well before n_iterations
            self.eta_seconds = None
            eta = f", objective decreasing by {decrease:.1e}"
        elif frac > 0.01:
            self.eta_seconds = elapsed * (1.0 - frac) / frac
            eta = f", about {format_seconds(self.eta_seconds)} left"
        else:
            eta = ""
        loss = getattr(progress, "loss", float("nan"))
        loss_txt = f", loss {loss:.4g}" if np.isfinite(loss) else ""
        self.status.value = (
            f"{progress.stage} ({progress.stage_index + 1}/{progress.n_stages}): "
            f"iteration {progress.iteration}/{progress.n_iterations}{loss_txt}; "
            f"{format_seconds(elapsed)} elapsed{eta}"
        )

    def finish(self, text: str, done: bool = True) -> None:
        """Show the end of a run (a full bar when ``done``)."""
        if done:
            self.bar.value = 1000
        self.status.value = f"{text} ({format_seconds(self._elapsed())})"


class _Failure:
    """What the worker returns when the core raised: shown as a notification."""

    def __init__(self, exc: BaseException):
        self.exc = exc
        self.traceback = traceback.format_exc()


def _guarded(make_generator, preview_every: int, cancel: threading.Event | None = None):
    """Run ``make_generator()``'s generator with previews every ``preview_every`` records, on the
    plugin's torch thread (``_torch_thread``), stoppable by ``cancel``; turn an exception into a
    returned :class:`_Failure` (a cancelled run returns None)."""
    try:
        result = yield from iterate(with_previews(make_generator(), preview_every, share=PREVIEW_SHARE), cancel)
    except Cancelled:
        return None
    except Exception as exc:  # noqa: BLE001 - reported to the user, with the traceback logged
        return _Failure(exc)
    return result


def _kept(box: list, *args):
    """:func:`_guarded`'s generator, appended to ``box`` so that the widget can close it.

    A worker that is told to quit stops asking for records and ends, but
    leaves its generator suspended (and napari keeps the worker): closing it
    closes the solver, whose tensors (on the GPU too) are then freed.
    """
    box.append(_guarded(*args))
    return (yield from box[-1])


class SolverWidget(Container):
    """Base of the solver dock widgets: input layer, Run / Cancel, progress, a thread worker.

    Subclasses add their fields to ``self.form``, lay the widget out with
    :meth:`assemble` and implement :meth:`make_job` (returning a zero-argument
    callable that returns the core's generator; it runs in the worker thread)
    and :meth:`on_result` (adds layers; runs in the GUI thread).
    :meth:`on_progress`, :meth:`preview_every` and :meth:`cleanup` may be
    overridden for previews.

    Attributes
    ----------
    form : magicgui.widgets.Container
        The parameters; ``form.layer`` is the input layer.
    last_result, last_layers
        The result of the latest run and the layers it added.
    """

    title = "lfdeblur"

    def __init__(self, napari_viewer):
        self.viewer = napari_viewer
        self.worker = None
        self._kept = []  # the running worker's generator (see _kept)
        self.input_placement = ((1.0,) * 4, (0.0,) * 4)  # (scale, translate) of the input layer of the last run
        self._gone = False  # the widget's Qt side was deleted (the viewer closed): signals update nothing
        self._cancelled = False
        self._cancel_event = threading.Event()
        self._cancel_reported = False
        self.last_result = None
        self.last_layers: list = []
        self.layer_combo = LayerChoice(napari_viewer, predicate=is_lightfield, name="layer", label="input layer",
                                       tooltip="the 4D light-field layer to work on (it is never modified)")
        self.form = Container(name="form", widgets=[self.layer_combo])
        self.run_button = PushButton(name="run_button", text="Run")
        self.cancel_button = PushButton(name="cancel_button", text="Cancel", enabled=False)
        self.run_button.changed.connect(self.run)
        self.cancel_button.changed.connect(self.cancel)
        self.progress = ProgressPanel()
        super().__init__(labels=False)

    def follow_input(self, callback) -> None:
        """Call ``callback()`` now, when another input layer is chosen, and when the chosen layer's metadata is
        replaced (another widget's re-run updates its result layer in place, with the path it was made with)."""
        watched = []

        def changed(*_):  # the layer outlives the widget: once the widget is gone, it lets the layer go
            if self._gone:
                forget()
            else:
                callback()

        def forget(*_):
            for layer in watched:
                layer.events.metadata.disconnect(changed)
            watched.clear()

        def rewatch(*_):
            forget()
            if self.layer_combo.value is not None:
                watched.append(self.layer_combo.value)
                watched[0].events.metadata.connect(changed)
            callback()

        self.layer_combo.changed.connect(rewatch)
        self.native.destroyed.connect(forget)
        rewatch()

    def assemble(self, before=(), after=()) -> None:
        """Lay out: the form, ``before``, Run / Cancel, the progress panel, ``after``."""
        buttons = Container(layout="horizontal", widgets=[self.run_button, self.cancel_button], labels=False)
        buttons.margins = (0, 0, 0, 0)
        self.extend([self.form, *before, buttons, self.progress, *after])
        self.native.layout().addStretch(1)
        self.native.destroyed.connect(self._quit_worker)

    # ----------------------------------------------------------- hooks
    def make_job(self, layer, lf):  # pragma: no cover - abstract
        raise NotImplementedError

    def on_result(self, result) -> None:  # pragma: no cover - abstract
        raise NotImplementedError

    def on_progress(self, progress) -> None:
        """Show a progress record beyond the progress bar (previews, plots)."""

    def preview_every(self) -> int:
        """Records between two light-field previews (0: none)."""
        return 0

    def cleanup(self) -> None:
        """Remove temporary layers (previews); called on cancel, error and success (after
        :meth:`on_result`, which may take them over as result layers)."""

    # ----------------------------------------------------------- state
    @property
    def is_running(self) -> bool:
        return self.worker is not None

    def input_lightfield(self):
        """``(layer, lf)`` of the chosen input layer, or None after a notification."""
        layer = self.layer_combo.value
        try:
            lf = lightfield_from_layer(layer)
        except LayerError as exc:
            notify_error(f"{self.title}: {exc}")
            return None
        return layer, lf

    def add_result(self, layer_data):
        """Add (or update) a layer of this run's results, placed over the input layer (:func:`add_layer`)."""
        return add_layer(self.viewer, placed(layer_data, *self.input_placement))

    def run(self, *_):
        """Start the job in a worker thread (returns the worker, or None)."""
        if self.is_running:
            notify_info(f"{self.title} is already running")
            return None
        picked = self.input_lightfield()
        if picked is None:
            return None
        self.input_placement = (tuple(picked[0].scale), tuple(picked[0].translate))
        try:
            job = self.make_job(*picked)
        except (ValueError, LayerError) as exc:
            notify_error(f"{self.title}: {exc}")
            self.progress.status.value = f"{self.title}: not started (see the error)"  # not the last run's 'done'
            return None
        self._cancelled = False
        self._cancel_event = threading.Event()
        self._cancel_reported = False
        self.last_result = None
        self.last_layers = []
        self.progress.start(f"{self.title}: starting...")
        self._kept = []
        worker = thread_worker(_kept, start_thread=False)(self._kept, job, self.preview_every(), self._cancel_event)
        worker.yielded.connect(self._on_yielded)
        worker.returned.connect(self._on_returned)
        worker.aborted.connect(self._on_aborted)
        worker.finished.connect(self._on_finished)
        self.worker = worker
        self.run_button.enabled = False
        self.cancel_button.enabled = True
        _run_starts()
        worker.start()
        return worker

    def run_and_wait(self, timeout: float | None = None) -> list:
        """Run and wait for the end, processing Qt events (for scripts and tests).

        Parameters
        ----------
        timeout : float, optional
            Seconds after which the run is cancelled.

        Returns
        -------
        list of layers
            The layers the run added; empty when it failed or was cancelled
            (a notification says why).
        """
        from qtpy.QtWidgets import QApplication

        self.last_layers = []
        if self.run() is None:
            return []
        t0 = time.perf_counter()
        while self.is_running:
            QApplication.processEvents()
            time.sleep(0.005)
            if timeout is not None and time.perf_counter() - t0 > timeout and not self._cancelled:
                self.cancel()
        QApplication.processEvents()
        return list(self.last_layers)

    def cancel(self, *_):
        """Ask the worker to stop at the solver's next cancellation point or progress report; no result
        layer is added."""
        if self.worker is None:
            return
        self._cancelled = True
        self._cancel_event.set()
        self.worker.quit()
        self.progress.status.value = f"{self.title}: cancelling..."

    def _quit_worker(self, *_):
        """Stop a running worker when the widget goes away; its late signals then touch no deleted widget."""
        self._gone = True
        if self.worker is not None:
            self._cancelled = True
            self._cancel_event.set()
            try:
                self.worker.quit()
            except RuntimeError:  # pragma: no cover - Qt objects already deleted
                pass

    # --------------------------------------------------------- signals
    def _on_yielded(self, progress):
        if self._cancelled or self._gone:
            return
        try:
            self.progress.update_progress(progress)
            self.on_progress(progress)
        except Exception as exc:  # noqa: BLE001 - a preview must never crash the GUI
            log.exception("progress display failed")
            notify_warning(f"{self.title}: progress display failed: {exc}")

    def _on_returned(self, result):
        if self._cancelled or self._gone:
            return
        if isinstance(result, _Failure):
            self.cleanup()
            log.error("%s failed:\n%s", self.title, result.traceback)
            notify_error(f"{self.title} failed: {result.exc}")
            self.progress.finish(f"failed: {result.exc}", done=False)
            return
        try:
            self.last_result = result
            self.on_result(result)
        except Exception as exc:  # noqa: BLE001
            log.exception("adding result layers failed")
            notify_error(f"{self.title}: could not add the result: {exc}")
            return
        finally:
            self.cleanup()
        self.progress.finish(f"{self.title}: done")

    def _on_aborted(self):
        self._cancel_reported = True
        if self._gone:
            return
        self.cleanup()
        self.progress.finish(f"{self.title}: cancelled, nothing added", done=False)
        notify_info(f"{self.title}: cancelled")

    def _on_finished(self):
        _run_ends()  # on the main thread, after the worker put back what it found
        for gen in self._kept:  # the worker has ended: a run it quit is suspended, and is closed here
            gen.close()
        self._kept = []
        if self._gone:
            self.worker = None
            return
        if self._cancelled:
            # stopped at a cancellation point, the worker returns without an 'aborted' signal
            if self._cancel_reported:
                self.cleanup()
            else:
                self._on_aborted()
        self.worker = None
        self.run_button.enabled = True
        self.cancel_button.enabled = False
