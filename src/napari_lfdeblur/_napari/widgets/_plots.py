"""Small matplotlib plots for the dock widgets, each its own magicgui widget.

- :class:`PathPlot`: ``p_x``, ``p_y``, ``p_z`` of a camera path against ``t``;
- :class:`LossPlot`: the objective against iteration.

During a run they are redrawn with ``live=True``: drawn at once and without
the layout engine (the layout is most of the cost of a redraw); otherwise
they are laid out and drawn when Qt is next idle.
"""

from __future__ import annotations

import numpy as np
from magicgui.widgets import Container

from ...path import bezier_positions, validate_control_points

__all__ = ["PathPlot", "LossPlot"]


def _figure_canvas(width=3.2, height=1.9):
    from matplotlib.backends.backend_qtagg import FigureCanvasQTAgg
    from matplotlib.figure import Figure
    from qtpy.QtWidgets import QSizePolicy

    fig = Figure(figsize=(width, height), dpi=90, layout="constrained")
    canvas = FigureCanvasQTAgg(fig)
    canvas.setSizePolicy(QSizePolicy.Policy.Expanding, QSizePolicy.Policy.Fixed)
    canvas.setFixedHeight(int(height * 90))
    return fig, canvas


def _redraw(figure, canvas, live: bool) -> None:
    """Draw a plot: now and without laying it out again (``live``), else laid out when Qt is idle."""
    figure.set_layout_engine("none" if live else "constrained")
    if live:
        canvas.draw()
    else:
        canvas.draw_idle()


class _PlotWidget(Container):
    """A magicgui widget holding one matplotlib figure with one axes."""

    def __init__(self, name: str, height: float):
        self.figure, self.canvas = _figure_canvas(height=height)
        self.ax = self.figure.add_subplot(111)
        super().__init__(name=name, labels=False)
        self.native.layout().addWidget(self.canvas)
        self.margins = (0, 0, 0, 0)

    def _finish(self, xlabel: str, ylabel: str, live: bool) -> None:
        ax = self.ax
        ax.set_xlabel(xlabel, fontsize=8)
        ax.set_ylabel(ylabel, fontsize=8)
        ax.tick_params(labelsize=7)
        ax.grid(alpha=0.3)
        _redraw(self.figure, self.canvas, live)


class PathPlot(_PlotWidget):
    """``p_x``, ``p_y``, ``p_z`` against ``t``: the path (solid) and a true one (dashed)."""

    COLORS = {"p_x": "tab:red", "p_y": "tab:green", "p_z": "tab:blue"}

    def __init__(self, name: str = "path_plot"):
        super().__init__(name, height=1.9)
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
        if ax.lines:
            ax.legend(fontsize=6, ncol=2, loc="best")
        self._finish("t", "views", live)


class LossPlot(_PlotWidget):
    """The objective against iteration (log scale); dotted lines where a new stage starts."""

    def __init__(self, name: str = "loss_plot"):
        super().__init__(name, height=1.6)
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
        self._finish("path iteration (dotted: new level / start)", "loss", live)

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
