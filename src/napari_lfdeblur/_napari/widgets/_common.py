"""Pieces shared by the dock widgets.

- :class:`LayerComboBox`: pick a layer by name, kept in sync with the viewer.
- :class:`PathTable`: an editable ``(n, 3)`` table of control points.
- :class:`PathPlot`, :class:`LossPlot`: small matplotlib plots.
- :class:`ProgressPanel`: a progress bar with a time-left estimate.
- :class:`EpiPanel`: horizontal and vertical EPI layers at a picked row/column.
- :class:`SolverWidget`: the base of the three widgets; runs a core generator
  in a napari ``thread_worker`` with Run / Cancel.
"""

from __future__ import annotations

import logging
import time
import traceback

import numpy as np
from napari.qt.threading import thread_worker
from napari.utils.notifications import show_error, show_info, show_warning
from qtpy.QtCore import Signal
from qtpy.QtWidgets import (
    QAbstractItemView,
    QCheckBox,
    QComboBox,
    QDoubleSpinBox,
    QFormLayout,
    QGroupBox,
    QHBoxLayout,
    QHeaderView,
    QLabel,
    QProgressBar,
    QPushButton,
    QSizePolicy,
    QSpinBox,
    QTableWidget,
    QTableWidgetItem,
    QVBoxLayout,
    QWidget,
)

from ...path import bezier_positions, validate_control_points
from ..layers import (
    LayerError,
    add_layer,
    epi_layer_data,
    layer_kind,
    lightfield_from_layer,
)

log = logging.getLogger(__name__)

__all__ = [
    "LayerComboBox",
    "PathTable",
    "PathPlot",
    "LossPlot",
    "ProgressPanel",
    "EpiPanel",
    "EpiWidget",
    "SolverWidget",
    "notify_error",
    "notify_info",
    "spin",
    "dspin",
]


def notify_error(message: str) -> None:
    """Show an error notification (never raises)."""
    log.info("lfdeblur error: %s", message)
    show_error(message)


def notify_info(message: str) -> None:
    """Show an info notification."""
    show_info(message)


def notify_warning(message: str) -> None:
    """Show a warning notification."""
    show_warning(message)


def spin(value: int, lo: int, hi: int, tip: str = "") -> QSpinBox:
    """An integer spin box."""
    box = QSpinBox()
    box.setRange(lo, hi)
    box.setValue(value)
    box.setToolTip(tip)
    return box


def dspin(value: float, lo: float, hi: float, step: float = 0.1, decimals: int = 3, tip: str = "") -> QDoubleSpinBox:
    """A floating-point spin box."""
    box = QDoubleSpinBox()
    box.setDecimals(decimals)
    box.setRange(lo, hi)
    box.setSingleStep(step)
    box.setValue(value)
    box.setToolTip(tip)
    return box


def device_combo() -> QComboBox:
    """auto / cpu / cuda."""
    box = QComboBox()
    box.addItems(["auto", "cpu", "cuda"])
    box.setToolTip("torch device: auto picks CUDA when available")
    return box


# --------------------------------------------------------------- layers


class LayerComboBox(QComboBox):
    """A combo box of the viewer's layers (by name), refreshed as layers come and go.

    Parameters
    ----------
    viewer : napari.Viewer
    predicate : callable, optional
        ``predicate(layer) -> bool`` keeps only some layers.
    allow_none : bool
        Offer an empty choice first.
    """

    def __init__(self, viewer, predicate=None, allow_none: bool = False, parent=None):
        super().__init__(parent)
        self._viewer = viewer
        self._predicate = predicate or (lambda layer: True)
        self._allow_none = allow_none
        self.setSizeAdjustPolicy(QComboBox.SizeAdjustPolicy.AdjustToMinimumContentsLengthWithIcon)
        self.setMinimumContentsLength(12)
        viewer.layers.events.inserted.connect(self.refresh)
        viewer.layers.events.removed.connect(self.refresh)
        viewer.layers.events.moved.connect(self.refresh)
        self.refresh()

    def refresh(self, *_):
        current = self.currentText()
        names = [layer.name for layer in self._viewer.layers if self._predicate(layer)]
        if self._allow_none:
            names = [""] + names
        self.blockSignals(True)
        self.clear()
        self.addItems(names)
        if current in names:
            self.setCurrentText(current)
        elif names:
            # the chosen layer is gone (or none was chosen): take the newest usable one
            self.setCurrentIndex(0 if self._allow_none else len(names) - 1)
        self.blockSignals(False)
        if self.currentText() != current:
            self.currentTextChanged.emit(self.currentText())

    def showPopup(self):
        self.refresh()
        super().showPopup()

    def current_layer(self):
        """The chosen layer, or None."""
        name = self.currentText()
        if name and name in self._viewer.layers:
            return self._viewer.layers[name]
        return None

    def set_layer(self, layer_or_name) -> None:
        """Choose a layer."""
        self.refresh()
        name = getattr(layer_or_name, "name", layer_or_name)
        self.setCurrentText(name)


def is_image(layer) -> bool:
    return layer_kind(layer) == "image"


def has_path(layer) -> bool:
    return "control_points" in getattr(layer, "metadata", {})


# ----------------------------------------------------------------- path


class PathTable(QWidget):
    """An editable table of Bezier control points ``(p_x, p_y, p_z)``, one per row."""

    changed = Signal()

    def __init__(self, control_points=None, parent=None):
        super().__init__(parent)
        self.table = QTableWidget(0, 3)
        self.table.setHorizontalHeaderLabels(["p_x (views)", "p_y (views)", "p_z (views/x~)"])
        self.table.horizontalHeader().setSectionResizeMode(QHeaderView.ResizeMode.Stretch)
        self.table.setSelectionBehavior(QAbstractItemView.SelectionBehavior.SelectRows)
        self.table.setMinimumHeight(110)
        self.table.setToolTip("Bezier control points of the camera path (MODEL.md units); edit freely")
        add = QPushButton("+ point")
        rem = QPushButton("- point")
        add.clicked.connect(self._add_row)
        rem.clicked.connect(self._remove_row)
        buttons = QHBoxLayout()
        buttons.addWidget(add)
        buttons.addWidget(rem)
        lay = QVBoxLayout(self)
        lay.setContentsMargins(0, 0, 0, 0)
        lay.addWidget(self.table)
        lay.addLayout(buttons)
        self.table.itemChanged.connect(lambda *_: self.changed.emit())
        self.set_control_points(np.zeros((2, 3)) if control_points is None else control_points)

    def set_control_points(self, control_points) -> None:
        """Fill the table with an ``(n, 3)`` array."""
        cp = validate_control_points(control_points)
        self.table.blockSignals(True)
        self.table.setRowCount(cp.shape[0])
        for i, row in enumerate(cp):
            for j, value in enumerate(row):
                value = 0.0 if abs(value) < 1e-9 else float(value)  # no '-0' or '1e-17'
                self.table.setItem(i, j, QTableWidgetItem(f"{value:.6g}"))
        self.table.blockSignals(False)
        self.changed.emit()

    def control_points(self) -> np.ndarray:
        """The table as a float64 ``(n, 3)`` array.

        Raises
        ------
        ValueError
            On an empty or non-numeric cell, or fewer than 2 rows.
        """
        rows = []
        for i in range(self.table.rowCount()):
            row = []
            for j in range(3):
                item = self.table.item(i, j)
                text = item.text().strip() if item is not None else ""
                try:
                    row.append(float(text))
                except ValueError:
                    raise ValueError(
                        f"control point {i + 1}, column {'xyz'[j]}: {text!r} is not a number"
                    ) from None
            rows.append(row)
        return validate_control_points(np.array(rows, dtype=np.float64).reshape(-1, 3))

    def _add_row(self):
        n = self.table.rowCount()
        self.table.blockSignals(True)
        self.table.insertRow(n)
        for j in range(3):
            prev = self.table.item(n - 1, j) if n else None
            self.table.setItem(n, j, QTableWidgetItem(prev.text() if prev else "0"))
        self.table.blockSignals(False)
        self.changed.emit()

    def _remove_row(self):
        n = self.table.rowCount()
        if n > 2:
            self.table.removeRow(n - 1)
            self.changed.emit()


def _figure_canvas(width=3.2, height=1.9):
    from matplotlib.backends.backend_qtagg import FigureCanvasQTAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(width, height), dpi=90, layout="constrained")
    canvas = FigureCanvasQTAgg(fig)
    canvas.setSizePolicy(QSizePolicy.Policy.Expanding, QSizePolicy.Policy.Fixed)
    canvas.setFixedHeight(int(height * 90))
    return fig, canvas


def _redraw(figure, canvas, live: bool) -> None:
    """Draw a plot: now and without laying it out again during a run (``live``; the layout
    is most of the cost of a redraw), else laid out, when Qt is next idle."""
    figure.set_layout_engine("none" if live else "constrained")
    if live:
        canvas.draw()
    else:
        canvas.draw_idle()


class PathPlot(QWidget):
    """``p_x``, ``p_y``, ``p_z`` against ``t``: the path (solid) and a true one (dashed)."""

    COLORS = {"p_x": "tab:red", "p_y": "tab:green", "p_z": "tab:blue"}

    def __init__(self, parent=None):
        super().__init__(parent)
        self.figure, self.canvas = _figure_canvas()
        self.ax = self.figure.add_subplot(111)
        lay = QVBoxLayout(self)
        lay.setContentsMargins(0, 0, 0, 0)
        lay.addWidget(self.canvas)
        self.lines = {}
        self.plot(None)

    def plot(self, control_points, true_control_points=None, n_times: int = 64, live: bool = False) -> None:
        """Redraw; either path may be None. ``live``: a quick redraw during a run."""
        ax = self.ax
        ax.clear()
        t = np.linspace(0, 1, max(2, n_times))
        for cps, style, tag in ((true_control_points, "--", "true"), (control_points, "-", "")):
            if cps is None:
                continue
            try:
                pos = bezier_positions(validate_control_points(cps), len(t))
            except ValueError:
                continue
            for j, key in enumerate(("p_x", "p_y", "p_z")):
                label = f"{key} {tag}".strip()
                ax.plot(t, pos[:, j], style, color=self.COLORS[key], lw=1.4, label=label)
        ax.set_xlabel("t", fontsize=8)
        ax.set_ylabel("views", fontsize=8)
        ax.tick_params(labelsize=7)
        ax.grid(alpha=0.3)
        if ax.lines:
            ax.legend(fontsize=6, ncol=2, loc="best")
        _redraw(self.figure, self.canvas, live)


class LossPlot(QWidget):
    """The objective against iteration (log scale); dotted lines where a new stage starts."""

    def __init__(self, parent=None):
        super().__init__(parent)
        self.figure, self.canvas = _figure_canvas(height=1.6)
        self.ax = self.figure.add_subplot(111)
        lay = QVBoxLayout(self)
        lay.setContentsMargins(0, 0, 0, 0)
        lay.addWidget(self.canvas)
        self.values: list[float] = []
        self.stage_starts: list[int] = []
        self._stage = None
        self.plot([])

    def plot(self, values, stage_starts=None, live: bool = False) -> None:
        """Redraw with ``values`` (and stage boundaries, indices into ``values``).

        ``live``: a quick redraw during a run.
        """
        self.values = [float(v) for v in values]
        if stage_starts is not None:
            self.stage_starts = list(stage_starts)
        ax = self.ax
        ax.clear()
        vals = np.asarray(self.values, dtype=float)
        ok = np.isfinite(vals)
        if ok.any():
            ax.plot(np.nonzero(ok)[0] + 1, vals[ok], color="tab:purple", lw=1.2)
            if np.all(vals[ok] > 0):
                ax.set_yscale("log")
            for start in self.stage_starts:
                if 0 < start < len(vals):
                    ax.axvline(start + 0.5, color="0.6", ls=":", lw=0.8)
        ax.set_xlabel("path iteration (dotted: new level / start)", fontsize=8)
        ax.set_ylabel("loss", fontsize=8)
        ax.tick_params(labelsize=7)
        ax.grid(alpha=0.3)
        _redraw(self.figure, self.canvas, live)

    def reset(self) -> None:
        """Forget all values and stages."""
        self._stage = None
        self.plot([], [])

    def append(self, value: float, stage=None) -> None:
        """Add one value; a ``stage`` different from the previous one marks a boundary."""
        if stage is not None and stage != self._stage:
            if self._stage is not None:
                self.stage_starts.append(len(self.values))
            self._stage = stage
        self.values.append(float(value))


# ------------------------------------------------------------- progress


def format_seconds(seconds: float) -> str:
    seconds = max(0.0, float(seconds))
    if seconds < 60:
        return f"{seconds:.0f} s"
    if seconds < 3600:
        return f"{int(seconds // 60)} min {int(seconds % 60):02d} s"
    return f"{int(seconds // 3600)} h {int(seconds % 3600 // 60):02d} min"


class ProgressPanel(QWidget):
    """A progress bar and a status line with the time left."""

    def __init__(self, parent=None):
        super().__init__(parent)
        self.bar = QProgressBar()
        self.bar.setRange(0, 1000)
        self.bar.setValue(0)
        self.bar.setTextVisible(True)
        self.label = QLabel("idle")
        self.label.setWordWrap(True)
        lay = QVBoxLayout(self)
        lay.setContentsMargins(0, 0, 0, 0)
        lay.addWidget(self.bar)
        lay.addWidget(self.label)
        self._t0 = None
        self.eta_seconds = None

    def start(self, text: str = "starting...") -> None:
        self._t0 = time.perf_counter()
        self.eta_seconds = None
        self.bar.setValue(0)
        self.bar.setFormat("%p%")
        self.label.setText(text)

    def update_progress(self, progress) -> None:
        """Show a :class:`napari_lfdeblur.progress.Progress` record."""
        frac = float(getattr(progress, "fraction", 0.0))
        self.bar.setValue(int(round(1000 * frac)))
        elapsed = time.perf_counter() - (self._t0 or time.perf_counter())
        if frac > 0.01:
            self.eta_seconds = elapsed * (1.0 - frac) / frac
            eta = f", about {format_seconds(self.eta_seconds)} left"
        else:
            eta = ""
        loss = getattr(progress, "loss", float("nan"))
        loss_txt = f", loss {loss:.4g}" if np.isfinite(loss) else ""
        self.label.setText(
            f"{progress.stage} ({progress.stage_index + 1}/{progress.n_stages}): "
            f"iteration {progress.iteration}/{progress.n_iterations}{loss_txt}; "
            f"{format_seconds(elapsed)} elapsed{eta}"
        )

    def finish(self, text: str, done: bool = True) -> None:
        if done:
            self.bar.setValue(1000)
        elapsed = time.perf_counter() - (self._t0 or time.perf_counter())
        self.label.setText(f"{text} ({format_seconds(elapsed)})")


# ------------------------------------------------------------------ EPI


class EpiPanel(QGroupBox):
    """Horizontal and vertical EPI layers of a light-field layer at a picked row/column.

    The horizontal EPI is ``lf[v, :, y, :]`` and the vertical one
    ``lf[:, u, :, x]`` (see :mod:`napari_lfdeblur._napari.layers` for their
    placement). Once shown, they follow the spin boxes; with *pick by
    clicking* on, a click on the canvas (whichever layer is selected) sets
    ``y``, ``x`` from the click and ``v``, ``u`` from the view sliders;
    clicks outside the light field (e.g. on an EPI) are ignored.
    """

    def __init__(self, viewer, parent=None):
        super().__init__("Epipolar images", parent)
        self._viewer = viewer
        self.layer_combo = LayerComboBox(viewer, predicate=_is_lightfield)
        self.v_spin = spin(0, 0, 0, "view row v of the horizontal EPI")
        self.y_spin = spin(0, 0, 0, "pixel row y of the horizontal EPI")
        self.u_spin = spin(0, 0, 0, "view column u of the vertical EPI")
        self.x_spin = spin(0, 0, 0, "pixel column x of the vertical EPI")
        self.show_button = QPushButton("Show EPIs")
        self.click_box = QCheckBox("pick by clicking")
        self.click_box.setToolTip("click on the canvas to set y, x from the click (and v, u from the view sliders)")
        form = QFormLayout(self)
        form.addRow("layer", self.layer_combo)
        row1 = QHBoxLayout()
        for label, box in (("v", self.v_spin), ("y", self.y_spin), ("u", self.u_spin), ("x", self.x_spin)):
            row1.addWidget(QLabel(label))
            row1.addWidget(box)
        form.addRow(row1)
        row2 = QHBoxLayout()
        row2.addWidget(self.show_button)
        row2.addWidget(self.click_box)
        form.addRow(row2)
        self._active = False
        self.layer_combo.currentTextChanged.connect(self._layer_changed)
        for box in (self.v_spin, self.y_spin, self.u_spin, self.x_spin):
            box.valueChanged.connect(self._pick_changed)
        self.show_button.clicked.connect(self.show_epis)
        self.click_box.toggled.connect(self._toggle_click)
        self._layer_changed()

    # names of the EPI layers of the chosen layer
    def layer_names(self):
        layer = self.layer_combo.current_layer()
        base = layer.name if layer is not None else ""
        return f"{base} EPI h", f"{base} EPI v"

    def _layer_changed(self, *_):
        layer = self.layer_combo.current_layer()
        if layer is None:
            return
        shape = layer.data.shape
        V, U, Y, X = shape[:4]
        for box, n in ((self.v_spin, V), (self.u_spin, U), (self.y_spin, Y), (self.x_spin, X)):
            box.blockSignals(True)
            box.setRange(0, n - 1)
            box.setValue(n // 2)
            box.blockSignals(False)
        self._active = False

    def set_pick(self, v=None, y=None, u=None, x=None) -> None:
        """Set the picked rows/columns (updates the EPI layers once shown)."""
        for box, value in ((self.v_spin, v), (self.y_spin, y), (self.u_spin, u), (self.x_spin, x)):
            if value is not None:
                box.blockSignals(True)
                box.setValue(int(value))
                box.blockSignals(False)
        self._pick_changed()

    def _pick_changed(self, *_):
        if self._active:
            self.show_epis()

    def show_epis(self, *_):
        """Add (or update) the two EPI layers; returns them, or None on error."""
        layer = self.layer_combo.current_layer()
        try:
            lf = _lightfield_view(layer)
        except LayerError as exc:
            notify_error(f"EPIs: {exc}")
            return None
        h_name, v_name = self.layer_names()
        meta = {"source_layer": layer.name}
        h = add_layer(self._viewer, epi_layer_data(
            lf, "h", name=h_name, v=self.v_spin.value(), y=self.y_spin.value(), metadata=meta))
        v = add_layer(self._viewer, epi_layer_data(
            lf, "v", name=v_name, u=self.u_spin.value(), x=self.x_spin.value(), metadata=meta))
        self._active = True
        return h, v

    def _toggle_click(self, on: bool):
        """Listen (or stop listening) to clicks on the canvas, whichever layer is selected."""
        callbacks = self._viewer.mouse_drag_callbacks
        if on and self._on_click not in callbacks:
            callbacks.append(self._on_click)
        elif not on and self._on_click in callbacks:
            callbacks.remove(self._on_click)

    def _on_click(self, _viewer, event):
        layer = self.layer_combo.current_layer()
        if layer is None or not _is_lightfield(layer):
            return
        coords = layer.world_to_data(event.position)
        if len(coords) < 4:
            return
        v, u, y, x = (int(round(c)) for c in coords[:4])
        shape = layer.data.shape
        if not (0 <= y < shape[2] and 0 <= x < shape[3]):
            return  # a click outside the light field (e.g. on an EPI)
        self.set_pick(v=min(max(v, 0), shape[0] - 1), y=y, u=min(max(u, 0), shape[1] - 1), x=x)
        if not self._active:
            self.show_epis()


def _is_lightfield(layer) -> bool:
    if not is_image(layer) or getattr(layer, "multiscale", False):
        return False
    want = 5 if layer.rgb else 4
    return layer.data.ndim == want


def _lightfield_view(layer) -> np.ndarray:
    """The layer's data as a light field *without copying* (for EPIs; read only)."""
    if layer is None:
        raise LayerError("no light-field layer selected")
    if not _is_lightfield(layer):
        raise LayerError(f"layer {layer.name!r} is not a 4D light field (shape {layer.data.shape})")
    arr = np.asarray(layer.data)
    if np.issubdtype(arr.dtype, np.integer):
        return arr.astype(np.float32) / np.float32(np.iinfo(arr.dtype).max)
    return arr


# --------------------------------------------------------------- solver


class _Failure:
    """What the worker returns when the core raised: shown as a notification."""

    def __init__(self, exc: BaseException):
        self.exc = exc
        self.traceback = traceback.format_exc()


def _guarded(make_generator):
    """Run ``make_generator()``'s generator; turn an exception into a returned :class:`_Failure`."""
    try:
        result = yield from make_generator()
    except Exception as exc:  # noqa: BLE001 - reported to the user, with the traceback logged
        return _Failure(exc)
    return result


class SolverWidget(QWidget):
    """Base of the dock widgets: input layer, Run / Cancel, progress, a thread worker.

    Subclasses build their controls in ``self.form`` and implement
    :meth:`make_job` (returning a zero-argument callable that returns the
    core's generator; it runs in the worker thread) and :meth:`on_result`
    (adds layers; runs in the GUI thread). :meth:`on_progress` may be
    overridden for previews.
    """

    title = "lfdeblur"

    def __init__(self, napari_viewer, parent=None):
        super().__init__(parent)
        self.viewer = napari_viewer
        self.worker = None
        self._cancelled = False
        self.last_result = None
        self.last_layers: list = []
        self.layer_combo = LayerComboBox(napari_viewer, predicate=is_image)
        self.layer_combo.setToolTip("the 4D light-field layer to work on (it is never modified)")
        self.form = QFormLayout()
        self.form.addRow("input layer", self.layer_combo)
        self.run_button = QPushButton("Run")
        self.cancel_button = QPushButton("Cancel")
        self.cancel_button.setEnabled(False)
        self.run_button.clicked.connect(self.run)
        self.cancel_button.clicked.connect(self.cancel)
        self.progress = ProgressPanel()
        buttons = QHBoxLayout()
        buttons.addWidget(self.run_button)
        buttons.addWidget(self.cancel_button)
        self.main_layout = QVBoxLayout(self)
        self.main_layout.addLayout(self.form)
        self.extra_layout = QVBoxLayout()
        self.main_layout.addLayout(self.extra_layout)
        self.main_layout.addLayout(buttons)
        self.main_layout.addWidget(self.progress)
        self.after_layout = QVBoxLayout()
        self.main_layout.addLayout(self.after_layout)
        self.main_layout.addStretch(1)

    # ----------------------------------------------------------- hooks
    def make_job(self, layer, lf):  # pragma: no cover - abstract
        raise NotImplementedError

    def on_result(self, result) -> None:  # pragma: no cover - abstract
        raise NotImplementedError

    def on_progress(self, progress) -> None:
        pass

    def cleanup(self) -> None:
        """Remove temporary layers (previews); called on cancel, error and success."""

    # ----------------------------------------------------------- state
    @property
    def is_running(self) -> bool:
        return self.worker is not None

    def input_lightfield(self):
        """``(layer, lf)`` of the chosen input layer, or None after a notification."""
        layer = self.layer_combo.current_layer()
        try:
            lf = lightfield_from_layer(layer)
        except LayerError as exc:
            notify_error(f"{self.title}: {exc}")
            return None
        return layer, lf

    def run(self, *_):
        """Start the job in a worker thread (returns the worker, or None)."""
        if self.is_running:
            notify_info(f"{self.title} is already running")
            return None
        picked = self.input_lightfield()
        if picked is None:
            return None
        layer, lf = picked
        try:
            job = self.make_job(layer, lf)
        except (ValueError, LayerError) as exc:
            notify_error(f"{self.title}: {exc}")
            return None
        self._cancelled = False
        self.last_result = None
        self.last_layers = []
        self.progress.start(f"{self.title}: starting...")
        worker = thread_worker(_guarded, start_thread=False)(job)
        worker.yielded.connect(self._on_yielded)
        worker.returned.connect(self._on_returned)
        worker.aborted.connect(self._on_aborted)
        worker.finished.connect(self._on_finished)
        self.worker = worker
        self.run_button.setEnabled(False)
        self.cancel_button.setEnabled(True)
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
        """Ask the worker to stop at its next progress report; no result layer is added."""
        if self.worker is None:
            return
        self._cancelled = True
        self.worker.quit()
        self.progress.label.setText(f"{self.title}: cancelling...")

    # --------------------------------------------------------- signals
    def _on_yielded(self, progress):
        if self._cancelled:
            return
        try:
            self.progress.update_progress(progress)
            self.on_progress(progress)
        except Exception as exc:  # noqa: BLE001 - a preview must never crash the GUI
            log.exception("progress display failed")
            notify_warning(f"{self.title}: progress display failed: {exc}")

    def _on_returned(self, result):
        if self._cancelled:
            return
        self.cleanup()
        if isinstance(result, _Failure):
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
        self.progress.finish(f"{self.title}: done")

    def _on_aborted(self):
        self.cleanup()
        self.progress.finish(f"{self.title}: cancelled, nothing added", done=False)
        notify_info(f"{self.title}: cancelled")

    def _on_finished(self):
        if self._cancelled:
            self.cleanup()
        self.worker = None
        self.run_button.setEnabled(True)
        self.cancel_button.setEnabled(False)

    def closeEvent(self, event):  # pragma: no cover - GUI teardown
        if self.worker is not None:
            self._cancelled = True
            self.worker.quit()
        super().closeEvent(event)


class EpiWidget(QWidget):
    """Dock widget: the EPI panel on its own, for any light-field layer."""

    def __init__(self, napari_viewer, parent=None):
        super().__init__(parent)
        self.viewer = napari_viewer
        self.epi = EpiPanel(napari_viewer)
        lay = QVBoxLayout(self)
        lay.addWidget(self.epi)
        lay.addStretch(1)
