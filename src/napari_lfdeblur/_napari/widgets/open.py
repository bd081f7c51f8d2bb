"""The *Open light field* dock widget: *File > Open* with the reader's options.

napari's reader hook takes a path and nothing else, so it always opens every
view. This widget opens a light field with the options of
:func:`napari_lfdeblur.io.read_lightfield` that matter for large decodes:
``angular_crop`` (keep the central views; a Light Field Toolbox decode of a
Lytro Illum holds 15 x 15 views whose outer ones are dark, and people keep
9 x 9), the layout, when its detection needs help, and ``value_range``, for
values stored on another scale (12-bit data in a 16-bit file, floats beyond
[0, 1]). Where the layout allows it, only the kept views are read from disk.
The file is read in a worker thread; a file that cannot be read, or would
not fit in memory, becomes an error notification, and no layer is added or
replaced.
"""

from __future__ import annotations

import time
from pathlib import Path

from magicgui.widgets import CheckBox, ComboBox, Container, FileEdit, Label, LineEdit, PushButton
from napari.qt.threading import thread_worker

from ...io import LAYOUTS, parse_value_range, probe_layout
from ..layers import add_layer
from ..reader import read_lightfield_layer
from ._controls import heading, notify_error, notify_info, spin

__all__ = ["OpenLightFieldWidget"]

_CROP_TIP = ("keep only the central views, n_v x n_u (0: all views). A Light Field Toolbox decode of a "
             "Lytro Illum is 15 x 15 and its outer views are dark: 9 x 9 is usual. Layouts that store "
             "views separately (folders, HDF5, MATLAB v7.3, .npy) read only the kept views.")
_RANGE_TIP = ("the stored values that become 0 and 1: LO,HI (such as 0,4095 for 12-bit data in a 16-bit file) "
              "or auto (the data's own minimum and maximum); empty: integers by their type's maximum, floats as "
              "they are (they must lie in [0, 1]). Dark data show the blind solver few edges: stretch them.")


class OpenLightFieldWidget(Container):
    """Dock widget: open a light field with an angular crop and a chosen layout.

    Fields: ``source`` (a file, or a folder of views with *folder of views*
    ticked), ``views_v`` and ``views_u`` (central views kept, 0 for all),
    ``layout`` (``'auto'`` or one of :data:`napari_lfdeblur.io.LAYOUTS`),
    ``value_range`` (empty, ``auto`` or ``LO,HI``), *Open* and a status
    line. The new layer is added beside any layer of the same name (napari
    makes the name unique); nothing is replaced. A file that holds its
    camera path also gets a path layer, ``'<layer name> path'``. From a
    script, :meth:`open_and_wait` returns the new light-field layer.
    """

    def __init__(self, napari_viewer):
        self.viewer = napari_viewer
        self.worker = None
        self.last_layer = None
        self.source = FileEdit(name="source", label="file", mode="r",
                               tooltip="a light-field file (.mat, .h5, .npy, .npz, .tif, .eslf.png)")
        self.folder_box = CheckBox(name="folder", text="folder of views", value=False,
                                   tooltip="open a folder of view images (Lytro toolbox, HCI, Stanford names)")
        self.views_v = spin("views_v", 0, 0, 99, label="views kept (rows)", tooltip=_CROP_TIP)
        self.views_u = spin("views_u", 0, 0, 99, label="views kept (columns)", tooltip=_CROP_TIP)
        self.layout_combo = ComboBox(name="layout", label="layout", choices=("auto",) + LAYOUTS, value="auto",
                                     tooltip="how the file stores the views; 'auto' detects it")
        self.value_range = LineEdit(name="value_range", label="value range", value="", tooltip=_RANGE_TIP)
        self.open_button = PushButton(name="open_button", text="Open")
        self.status = Label(name="status", value="choose a file")
        super().__init__(widgets=[heading("Open a light field"), self.source, self.folder_box, self.views_v,
                                  self.views_u, self.layout_combo, self.value_range, self.open_button, self.status])
        self.folder_box.changed.connect(self._folder_toggled)
        self.source.changed.connect(self._source_changed)
        self._gone = False  # the Qt side was deleted (the viewer closed during a read): the read's end adds nothing
        self.native.destroyed.connect(self._forget)
        self.open_button.changed.connect(self.open)
        self.native.layout().addStretch(1)

    def _folder_toggled(self, on: bool):
        self.source.mode = "d" if on else "r"

    def _source_changed(self, *_):
        path = self._path()
        if path is None:
            self.status.value = "choose a file"
            return
        try:
            layout = probe_layout(path)
        except Exception:  # noqa: BLE001 - a status line, never a traceback
            layout = None
        self.status.value = (f"layout: {layout}" if layout else
                             "not recognised as a light field; choose its layout to try anyway")

    def _path(self) -> Path | None:
        value = self.source.value
        if value is None or str(value) in ("", "."):
            return None
        return Path(value)

    def angular_crop(self) -> tuple[int, int] | None:
        """The crop the form asks for: ``(n_v, n_u)``, or None for all views.

        Raises
        ------
        ValueError
            When only one of the two numbers is set.
        """
        n_v, n_u = self.views_v.value, self.views_u.value
        if n_v == 0 and n_u == 0:
            return None
        if n_v == 0 or n_u == 0:
            raise ValueError("set both numbers of views kept, or neither (0 keeps all views)")
        return n_v, n_u

    def open(self, *_):
        """Read the chosen light field in a worker thread; returns the worker, or None on bad input."""
        if self.worker is not None:
            return None
        path = self._path()
        if path is None:
            notify_error("Open a light field: choose a file first")
            return None
        try:
            crop = self.angular_crop()
            value_range = parse_value_range(self.value_range.value)
        except ValueError as exc:
            notify_error(f"Open a light field: {exc}")
            return None
        options = {} if crop is None else {"angular_crop": crop}
        if value_range is not None:
            options["value_range"] = value_range
        if self.layout_combo.value != "auto":
            options["layout"] = self.layout_combo.value
        self.status.value = f"reading {path.name} ..."
        self.open_button.enabled = False
        worker = thread_worker(_read, start_thread=False)(path, options)
        worker.returned.connect(self._on_returned)
        worker.finished.connect(self._on_finished)
        self.worker = worker
        worker.start()
        return worker

    def open_and_wait(self):
        """Open and wait for the read to end, processing Qt events (for scripts and tests).

        Returns
        -------
        napari.layers.Image or None
            The new layer; None when the file could not be read (a
            notification says why).
        """
        from qtpy.QtWidgets import QApplication

        self.last_layer = None
        if self.open() is None:
            return None
        while self.worker is not None:
            QApplication.processEvents()
            time.sleep(0.005)
        return self.last_layer

    def _forget(self, *_):
        self._gone = True

    def _on_returned(self, outcome):
        if self._gone:
            return
        path, result = outcome
        if isinstance(result, Exception):
            self.status.value = "not opened"
            notify_error(f"Open a light field: {result}")
            return
        layer = self.last_layer = add_layer(self.viewer, result[0], replace=False)
        for data, kwargs, kind in result[1:]:  # the camera path the file holds, named after the layer it drew
            meta = {**kwargs["metadata"], "source_layer": layer.name}
            add_layer(self.viewer, (data, {**kwargs, "name": f"{layer.name} path", "metadata": meta}, kind),
                      replace=False)
        shape = " x ".join(str(n) for n in layer.data.shape)
        self.status.value = f"opened {path.name}: {shape}"
        notify_info(f"opened {path.name} as {layer.name!r} ({shape})")

    def _on_finished(self, *_):
        self.worker = None
        if not self._gone:
            self.open_button.enabled = True


def _read(path: Path, options: dict):
    """Read in the worker; an error is returned, not raised (it becomes a notification)."""
    try:
        return path, read_lightfield_layer(path, **options)
    except Exception as exc:  # noqa: BLE001 - reported to the user in one line
        return path, exc
