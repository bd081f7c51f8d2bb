"""Form pieces shared by the dock widgets, built from ``magicgui.widgets``.

- :func:`spin`, :func:`fspin`, :func:`device_choice`: value widgets with the
  plugin's ranges and tooltips;
- :class:`LayerChoice`: a combo box of the viewer's layers, kept in sync with it;
- :class:`PathTable`: an editable ``(n, 3)`` (``(n, 6)`` with rotation) table of
  Bezier control points;
- :class:`PathSource`: take a path from another layer or a JSON file;
- :func:`heading`: a section heading;
- :func:`placed`: a result's layer data placed as its input layer lies in the world;
- ``notify_*``: napari notifications.
"""

from __future__ import annotations

import logging
import math

import numpy as np
from magicgui.widgets import CheckBox, ComboBox, Container, FileEdit, FloatSpinBox, Label, PushButton, SpinBox, Table
from napari.utils.notifications import show_error, show_info, show_warning

from ...io import PATH_FIELDS
from ...io._write import check_path_field
from ...path import MAX_ROTATION, path_view_mismatch, read_path_json, validate_control_points
from ..layers import LayerError, control_points_from_layer, layer_kind

log = logging.getLogger(__name__)

__all__ = [
    "INFINITY_DISPARITY_TIP",
    "DEVICES",
    "ROTATION_COLUMNS",
    "LayerChoice",
    "PathSource",
    "PathTable",
    "device_choice",
    "fspin",
    "infinity_disparity_field",
    "has_path",
    "heading",
    "is_image",
    "is_lightfield",
    "placed",
    "notify_error",
    "notify_info",
    "notify_warning",
    "fill_path",
    "warn_view_mismatch",
    "set_stated",
    "spin",
]

#: the device choices of every widget
DEVICES = ("auto", "cpu", "cuda")

#: the tooltip of the *infinity disparity* field of the widgets that restore a capture
INFINITY_DISPARITY_TIP = (
    "disparity of points at infinity d_inf, px/view (0: a camera focused at infinity); filled in from the "
    "layer or path when they state it. With the views' zero disparity on the focal plane, it is about the "
    "disparity of the farthest content (sky, a far wall); it cannot be estimated from the blur (docs/blind.md)")


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


def set_stated(field, value, source: str) -> bool:
    """Set a numeric form field to a value a layer or a file states.

    A value the field cannot take (not a number, not an integer for an
    integer field, outside the field's range) is left out with a warning
    notification naming ``source``; the field keeps its value.

    Returns
    -------
    bool
        Whether the field took the value.
    """
    whole = isinstance(value, (int, np.integer)) and not isinstance(value, bool)  # as lfdeblur reads it: no 8.0
    usable = whole if isinstance(field, SpinBox) else whole or isinstance(value, (float, np.floating))
    number = float(value) if usable else math.nan
    usable = usable and field.min <= number <= field.max
    if usable:
        field.value = int(number) if isinstance(field, SpinBox) else number
        if abs(field.value - number) > 1e-12 * max(1.0, abs(number)):  # the field's decimals rounded it
            notify_warning(f"{source} states {field.name} = {number!r}; the form holds {field.value!r}, "
                           "which is used")
    else:
        notify_warning(f"{source} states {field.name} = {value!r}, which this form cannot take "
                       f"({field.min:g} to {field.max:g}); {field.name} stays {field.value:g}")
    return usable


def fill_path(form, table, control_points, metadata, source: str) -> None:
    """Put a path found in a layer or a file into ``table``, and the ``n_times`` and ``infinity_disparity``
    that ``metadata`` states into the fields of ``form`` (through :func:`set_stated`).

    The ``view_shape`` it states goes to the table; an unusable one is left out with a warning.
    """
    metadata = metadata or {}
    for key in ("n_times", "infinity_disparity"):
        if key in metadata:
            set_stated(form[key], metadata[key], source)
    view_shape = None
    if metadata.get("view_shape") is not None:
        try:
            view_shape = check_path_field("view_shape", metadata["view_shape"], source)
        except ValueError as exc:
            notify_warning(f"{exc}; the path will not be checked against the views' size")
    table.set_control_points(control_points, view_shape)


def warn_view_mismatch(title: str, table, shape) -> None:
    """A warning notification when the path of ``table`` is for views of another size than a light field of
    ``shape`` (:func:`~napari_lfdeblur.path.path_view_mismatch`); it runs all the same."""
    note = path_view_mismatch(table.control_points(), shape, table.view_shape)
    if note:
        notify_warning(f"{title}: {note}")


def spin(name: str, value: int, lo: int, hi: int, label: str | None = None, tooltip: str = "") -> SpinBox:
    """An integer field of a form."""
    return SpinBox(name=name, label=label or name, value=value, min=lo, max=hi, tooltip=tooltip)


def fspin(name: str, value: float, lo: float, hi: float, step: float = 0.1, label: str | None = None,
          tooltip: str = "") -> FloatSpinBox:
    """A floating-point field of a form (the step sets the shown decimals)."""
    return FloatSpinBox(name=name, label=label or name, value=value, min=lo, max=hi, step=step, tooltip=tooltip)


def infinity_disparity_field(tooltip: str) -> FloatSpinBox:
    """The ``infinity_disparity`` field (px/view), to 4 decimals (a stated value keeps them); arrows step by 0.1."""
    field = fspin("infinity_disparity", 0.0, -20.0, 20.0, 1e-4, label="infinity disparity", tooltip=tooltip)
    field.native.setSingleStep(0.1)
    return field


def device_choice() -> ComboBox:
    """The ``device`` field: auto / cpu / cuda."""
    return ComboBox(name="device", choices=DEVICES, value="auto",
                    tooltip="torch device: auto picks CUDA when available")


def heading(text: str) -> Label:
    """A bold section heading."""
    return Label(value=f"<b>{text}</b>")


# ---------------------------------------------------------------- layers


def is_image(layer) -> bool:
    """Whether ``layer`` is an Image layer."""
    return layer_kind(layer) == "image"


def has_path(layer) -> bool:
    """Whether ``layer``'s metadata holds a camera path."""
    return "control_points" in getattr(layer, "metadata", {})


def is_lightfield(layer) -> bool:
    """Whether ``layer`` is a 4D (5D RGB) single-scale Image layer."""
    if not is_image(layer) or getattr(layer, "multiscale", False):
        return False
    return layer.data.ndim == (5 if layer.rgb else 4)


class LayerChoice(ComboBox):
    """A combo box of the viewer's layers, refreshed as layers come and go.

    Its ``value`` is the chosen layer (or None). When the chosen layer goes
    away, or none was chosen, the newest usable layer is taken (none, for a
    ``nullable`` choice).

    Parameters
    ----------
    viewer : napari.Viewer
    predicate : callable, optional
        ``predicate(layer) -> bool`` keeps only some layers.
    nullable : bool
        Offer an empty choice first.
    **kwargs
        ``name``, ``label``, ``tooltip`` of the field.
    """

    def __init__(self, viewer, predicate=None, nullable: bool = False, **kwargs):
        self._viewer = viewer
        self._predicate = predicate or (lambda layer: True)
        super().__init__(choices=self._layer_choices, nullable=nullable, **kwargs)
        for event in (viewer.layers.events.inserted, viewer.layers.events.removed, viewer.layers.events.moved):
            event.connect(self.reset_choices)
        self.reset_choices()

    def _layer_choices(self, _widget=None):
        return [(layer.name, layer) for layer in self._viewer.layers if self._predicate(layer)]

    def reset_choices(self, *_):
        """Re-read the viewer's layers, keeping the chosen one when it is still there."""
        previous = self.value
        super().reset_choices()
        layers = [layer for layer in self.choices if layer is not None]
        if previous is not None and any(layer is previous or layer == previous for layer in layers):
            if self.value is not previous:
                self.value = previous
        elif not self._nullable and layers:
            self.value = layers[-1]
        elif self._nullable:
            self.value = None

    def set_layer(self, layer_or_name) -> None:
        """Choose a layer (or a layer name)."""
        self.reset_choices()
        name = getattr(layer_or_name, "name", layer_or_name)
        self.value = self.get_choice(name)


# ------------------------------------------------------------------ path

COLUMNS = ("p_x (views)", "p_y (views)", "p_z (views/x~)")
#: the three more columns of a path with camera rotation (docs/model.md, "Camera rotation")
ROTATION_COLUMNS = ("r_x (rad)", "r_y (rad)", "r_z (rad)")
_NAMES = ("p_x", "p_y", "p_z", "r_x", "r_y", "r_z")


def _shown(value: float) -> float:
    """A number as a table cell shows it: to 6 significant digits, with no '-0' or '1e-17'."""
    return 0.0 if abs(value) < 1e-9 else float(f"{value:.6g}")


class PathTable(Container):
    """An editable table of Bezier control points, one per row.

    The columns are ``(p_x, p_y, p_z)``; ticking *rotation* adds ``(r_x,
    r_y, r_z)`` in radians (an ``(n, 6)`` path: pitch, yaw and roll, each
    within :data:`~napari_lfdeblur.path.MAX_ROTATION`). Unticking it hides
    the rotation columns (they come back if it is ticked again with as many
    rows). Its ``changed`` signal fires when a cell is edited, the points
    are set or the rotation columns are shown or hidden. ``view_shape`` is
    the ``(Y, X)`` of the views the path came with (None: not known, as for
    a preset), which :func:`warn_view_mismatch` compares with the input's.
    """

    def __init__(self, control_points=None, name: str = "path_table"):
        self.table = Table(name="table", tooltip="Bezier control points of the camera path "
                           "(units: docs/model.md); edit freely")
        self.table.min_height = 110
        self.add_button = PushButton(name="add_point", text="+ point")
        self.remove_button = PushButton(name="remove_point", text="- point")
        self.rotation = CheckBox(name="rotation", text="rotation", value=False, tooltip=(
            "add the camera rotation r_x (pitch), r_y (yaw), r_z (roll) in radians, each at most "
            f"{MAX_ROTATION} rad; handheld shake is a few mrad (0.005 rad moves the image by about "
            "0.005 max(Y, X) / 2 px)"))
        self._hidden_rotation, self._exact = None, {}
        self._syncing = False
        self.add_button.changed.connect(self._add_row)
        self.remove_button.changed.connect(self._remove_row)
        self.rotation.changed.connect(self._toggle_rotation)
        buttons = Container(layout="horizontal", widgets=[self.add_button, self.remove_button, self.rotation],
                            labels=False)
        buttons.margins = (0, 0, 0, 0)
        super().__init__(name=name, widgets=[self.table, buttons], labels=False)
        self.margins = (0, 0, 0, 0)
        self.set_control_points(np.zeros((2, 3)) if control_points is None else control_points)

    @property
    def n_columns(self) -> int:
        """3, or 6 when the rotation columns are shown."""
        return 6 if self.rotation.value else 3

    def _set_rows(self, rows) -> None:
        """Show ``rows`` (numbers rounded by :func:`_shown`; each kept exactly while its cell shows it)."""
        def number(v):
            return isinstance(v, (int, float)) and not isinstance(v, bool)

        self._exact = {(i, j): float(v) for i, r in enumerate(rows) for j, v in enumerate(r) if number(v)}
        rows = [[_shown(v) if number(v) else v for v in r] for r in rows]
        columns = COLUMNS + ROTATION_COLUMNS if self.rotation.value else COLUMNS
        # rows are numbered from 1, like the points in error messages
        self.table.value = {"data": rows, "index": list(range(1, len(rows) + 1)), "columns": list(columns)}
        # 3 columns share the width; 6 take what their numbers need (scrolling sideways in a narrow dock)
        header = self.table.native.horizontalHeader()
        header.setSectionResizeMode(header.ResizeMode.ResizeToContents if len(columns) > 3
                                    else header.ResizeMode.Stretch)
        header.setStretchLastSection(len(columns) > 3)
        self.table.min_height = 130 if len(columns) > 3 else 110  # room for the sideways scroll bar
        self.changed.emit(self)

    def set_control_points(self, control_points, view_shape=None) -> None:
        """Fill the table with an ``(n, 3)`` or ``(n, 6)`` array (shown to 6 significant digits, used exactly
        until a cell is edited).

        The *rotation* box follows the array's width. ``view_shape``: the
        ``(Y, X)`` of the views the path belongs to, when known.
        """
        cp = validate_control_points(control_points)
        self.view_shape = view_shape
        self._syncing = True
        try:
            self.rotation.value = cp.shape[1] == 6
        finally:
            self._syncing = False
        self._hidden_rotation = None
        self._set_rows(cp.tolist())

    def _cells(self) -> list:
        """The table's rows: each cell that still shows the number it was set to as that exact number, the
        others as they were typed."""
        return [[self._exact[i, j] if isinstance(cell, float) and (i, j) in self._exact
                 and cell == _shown(self._exact[i, j]) else cell for j, cell in enumerate(cells)]
                for i, cells in enumerate(self.table.data.to_list())]

    def control_points(self) -> np.ndarray:
        """The table as a float64 ``(n, 3)`` array, or ``(n, 6)`` when *rotation* is ticked.

        A cell that still shows the number it was set to (by
        :meth:`set_control_points`, a row added or the rotation shown again)
        gives that number exactly, not the 6 digits shown.

        Raises
        ------
        ValueError
            On an empty or non-numeric cell, a rotation beyond
            ``MAX_ROTATION``, or fewer than 2 rows.
        """
        rows = []
        for i, cells in enumerate(self._cells()):
            row = []
            for j, cell in enumerate(cells):
                try:
                    row.append(float(cell))
                except (TypeError, ValueError):
                    raise ValueError(f"control point {i + 1}, {_NAMES[j]}: {cell!r} is not a number") from None
                if j >= 3 and abs(row[-1]) > MAX_ROTATION:
                    raise ValueError(
                        f"control point {i + 1}, {_NAMES[j]}: {row[-1]:g} rad is beyond the largest rotation, "
                        f"{MAX_ROTATION} rad ({np.degrees(MAX_ROTATION):.1f} degrees); rotations are in radians"
                    )
            rows.append(row)
        return validate_control_points(np.array(rows, dtype=np.float64).reshape(-1, self.n_columns))

    def _toggle_rotation(self, *_):
        """Show (restoring hidden values, else zeros) or hide the rotation columns."""
        if self._syncing:
            return
        rows = self._cells()
        if self.rotation.value:
            hidden = self._hidden_rotation
            if hidden is None or len(hidden) != len(rows):
                hidden = [[0.0, 0.0, 0.0] for _ in rows]
            rows = [r[:3] + list(h) for r, h in zip(rows, hidden)]
        else:
            self._hidden_rotation = [r[3:6] for r in rows]
            rows = [r[:3] for r in rows]
        self._set_rows(rows)

    def _add_row(self, *_):
        rows = self._cells()
        self._set_rows(rows + [list(rows[-1]) if rows else [0.0] * self.n_columns])

    def _remove_row(self, *_):
        rows = self._cells()
        if len(rows) > 2:
            self._set_rows(rows[:-1])


class PathSource(Container):
    """Take a path from a layer holding one (*Take path*) or from a path JSON file.

    ``on_path(control_points, metadata)`` is called with the path found and
    the metadata it came with: a layer's (with the ``view_shape`` of a light
    field's own views when it states none), or for a file the ``n_times``,
    ``infinity_disparity`` and ``view_shape`` it states.
    """

    def __init__(self, viewer, on_path, title: str = "lfdeblur"):
        self._on_path = on_path
        self._title = title
        self.path_layer = LayerChoice(
            viewer, predicate=has_path, nullable=True, name="path_layer", label="take path from",
            tooltip="a layer whose metadata holds a camera path (path layers, results)")
        self.take_button = PushButton(name="take", text="Take path")
        self.json_file = FileEdit(name="json_file", label="path JSON", mode="r", filter="*.json",
                                  tooltip="a camera path saved by save_path_json / the writers")
        self.load_button = PushButton(name="load", text="Load path file", tooltip=(
            "read the chosen path JSON again: choosing a file reads it, but choosing the same file again "
            "(after it changed, or after the table was edited) does not"))
        self.take_button.changed.connect(self.take_path)
        self.json_file.changed.connect(self.load_json)
        self.load_button.changed.connect(lambda *_: self.load_json(say_why=True))
        super().__init__(name="path_source",
                         widgets=[self.path_layer, self.take_button, self.json_file, self.load_button])
        self.margins = (0, 0, 0, 0)

    def take_from(self, layer, quiet: bool = False) -> bool:
        """Hand on the path of ``layer``; False (and a notification unless ``quiet``) when it has none."""
        try:
            cp = control_points_from_layer(layer)
        except LayerError as exc:
            if not quiet:
                notify_error(f"{self._title}: {exc}")
            return False
        meta = dict(layer.metadata)
        shape = tuple(getattr(layer.data, "shape", ())) if layer_kind(layer) == "image" else ()
        if "view_shape" not in meta and len(shape) >= 4:
            meta["view_shape"] = list(shape[2:4])  # a light field's path is for its own views
        self._on_path(cp, meta)
        return True

    def take_path(self, *_):
        """Hand on the path of the layer chosen in *take path from*."""
        self.take_from(self.path_layer.value)

    def load_json(self, *_, say_why: bool = False):
        """Hand on the path of the chosen JSON file (``say_why``: a notification when none is chosen, as for
        *Load path file*; a file being chosen or typed is read once it ends in .json)."""
        name = self.json_file.value
        if not name or not str(name).lower().endswith(".json"):
            if say_why:
                notify_error(f"{self._title}: choose a path JSON file (.json) first")
            return
        try:
            cp, fields = read_path_json(name)
        except (OSError, ValueError) as exc:
            notify_error(f"{self._title}: {exc}")
            return
        self._on_path(cp, {key: fields[key] for key in PATH_FIELDS if key in fields})


def placed(layer_data, scale, translate):
    """``layer_data`` placed in the world as a layer of ``scale`` and ``translate`` lies: the data's own
    placement (in that layer's pixels: an EPI's beside it; none: over it) scaled by their last axes and moved
    by their ``translate``. A 2D layer (shapes, an EPI) takes the last two axes."""
    data, kwargs, kind = layer_data
    ndim = 2 if kind == "shapes" else np.ndim(data) - (1 if kwargs.get("rgb") else 0)
    scale, translate = np.asarray(scale, float)[-ndim:], np.asarray(translate, float)[-ndim:]
    own_scale = np.asarray(kwargs.get("scale", np.ones(ndim)), float)
    own_translate = np.asarray(kwargs.get("translate", np.zeros(ndim)), float)
    kwargs = dict(kwargs, scale=tuple(own_scale * scale), translate=tuple(translate + own_translate * scale))
    return data, kwargs, kind
