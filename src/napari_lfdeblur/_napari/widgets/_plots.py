"""Small matplotlib plots for the dock widgets, each its own magicgui widget.

- :class:`PathPlot`: ``p_x``, ``p_y``, ``p_z`` of a camera path against ``t``
  (and ``r_x``, ``r_y``, ``r_z`` in a second panel for a path with rotation);
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

#: dots per inch of the plots (the canvas height in px is the figure's height times this)
_DPI = 90


def _figure_canvas(width=3.2, height=1.9):
    from matplotlib.backends.backend_qtagg import FigureCanvasQTAgg
    from matplotlib.figure import Figure
    from qtpy.QtWidgets import QSizePolicy

    fig = Figure(figsize=(width, height), dpi=_DPI, layout="constrained")
    canvas = FigureCanvasQTAgg(fig)
    canvas.setSizePolicy(QSizePolicy.Policy.Expanding, QSizePolicy.Policy.Fixed)
    canvas.setFixedHeight(int(height * _DPI))
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

    @staticmethod
    def _style(ax, xlabel: str, ylabel: str) -> None:
        ax.set_xlabel(xlabel, fontsize=8)
        ax.set_ylabel(ylabel, fontsize=8)
        ax.tick_params(labelsize=7)
        ax.grid(alpha=0.3)

    def _finish(self, xlabel: str, ylabel: str, live: bool) -> None:
        self._style(self.ax, xlabel, ylabel)
        _redraw(self.figure, self.canvas, live)


def _positions(cps, n_times: int):
    """The path's positions at ``n_times`` instants, or None when ``cps`` is None or not a path."""
    if cps is None:
        return None
    try:
        return bezier_positions(validate_control_points(cps), n_times)
    except ValueError:
        return None


class PathPlot(_PlotWidget):
    """The path against ``t``: the path (solid) and a true one (dashed).

    The top axes (``ax``) show ``p_x``, ``p_y``, ``p_z`` in views. When
    either path has rotation columns, a second axes (``ax_rot``, else None)
    below shows ``r_x``, ``r_y``, ``r_z`` in milliradians.
    """

    COLORS = {"p_x": "tab:red", "p_y": "tab:green", "p_z": "tab:blue",
              "r_x": "tab:orange", "r_y": "tab:olive", "r_z": "tab:purple"}
    HEIGHT = 1.9
    ROTATION_HEIGHT = 1.5

    def __init__(self, name: str = "path_plot"):
        super().__init__(name, height=self.HEIGHT)
        self.ax_rot = None
        self.plot(None)

    def _set_panels(self, rotation: bool) -> None:
        """One axes, or two (translation above, rotation below) when ``rotation``."""
        if rotation == (self.ax_rot is not None):
            return
        self.figure.clear()
        if rotation:
            self.ax, self.ax_rot = self.figure.subplots(2, 1, sharex=True)
        else:
            self.ax, self.ax_rot = self.figure.add_subplot(111), None
        height = self.HEIGHT + (self.ROTATION_HEIGHT if rotation else 0.0)
        self.figure.set_figheight(height, forward=False)
        self.canvas.setFixedHeight(int(height * _DPI))

    def plot(self, control_points, true_control_points=None, n_times: int = 64, live: bool = False) -> None:
        """Redraw; either path may be None. ``live``: a quick redraw during a run."""
        t = np.linspace(0, 1, max(2, n_times))
        paths = [(_positions(cps, len(t)), style, tag)
                 for cps, style, tag in ((true_control_points, "--", "true"), (control_points, "-", ""))]
        self._set_panels(any(pos is not None and pos.shape[1] == 6 for pos, _, _ in paths))
        axes = [self.ax] if self.ax_rot is None else [self.ax, self.ax_rot]
        for ax in axes:
            ax.clear()
        for pos, style, tag in paths:
            if pos is None:
                continue
            for j, key in enumerate(("p_x", "p_y", "p_z", "r_x", "r_y", "r_z")[: pos.shape[1]]):
                ax, scale = (self.ax, 1.0) if j < 3 else (self.ax_rot, 1000.0)
                ax.plot(t, scale * pos[:, j], style, color=self.COLORS[key], lw=1.4, label=f"{key} {tag}".strip())
        for ax in axes:
            if ax.lines:
                ax.legend(fontsize=6, ncol=2, loc="best")
        if self.ax_rot is not None:
            self._style(self.ax, "", "views")
            self._style(self.ax_rot, "t", "rotation (mrad)")
        else:
            self._style(self.ax, "t", "views")
        _redraw(self.figure, self.canvas, live)


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
        from matplotlib.ticker import MaxNLocator

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
        ax.xaxis.set_major_locator(MaxNLocator(integer=True))  # iterations are counted: no 1.25
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
