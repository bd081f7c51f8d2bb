"""napari-lfdeblur: blind motion deblurring of 4D light fields.

Implements Srinivasan, Ng & Ramamoorthi, "Light Field Blind Motion
Deblurring" (CVPR 2017) as a Python library and a napari plugin.

The array layout, coordinates and units are those of docs/model.md: a light
field is a ``(V, U, Y, X)`` or ``(V, U, Y, X, C)`` float32 array in [0, 1], and
a camera path is a Bezier curve given by ``(n, 3)`` control points, or
``(n, 6)`` with a camera rotation.

Importing this package is cheap and needs neither Qt nor napari: public names
are loaded from their modules on first use.
"""

from __future__ import annotations

import importlib

__version__ = "0.1.0"

# public name -> module (relative to this package) that defines it
_PUBLIC = {
    # camera paths
    "bezier_positions": "path",
    "center_path": "path",
    "linear_path": "path",
    "arc_path": "path",
    "shake_path": "path",
    "shake6_path": "path",
    "random_path": "path",
    "preset_path": "path",
    "save_path_json": "path",
    "load_path_json": "path",
    "read_path_json": "path",
    "path_view_mismatch": "path",
    "path_in_frame": "path",
    "path_in_window": "path",
    # forward model
    "simulate_blur": "blur",
    "BlurOperator": "blur",
    # epipolar images
    "horizontal_epi": "epi",
    "vertical_epi": "epi",
    "view_shifts": "epi",
    "views_transposed": "epi",
    # sample data
    "synthetic_scene": "samples",
    "procedural_scene": "samples",
    "lytro_sample": "samples",
    # I/O
    "read_lightfield": "io",
    "write_lightfield": "io",
    "read_lightfield_with_metadata": "io",
    "detect_layout": "io",
    # non-blind deconvolution and the paper's analytic special cases
    "deconvolve": "deconvolution",
    "iter_deconvolve": "deconvolution",
    "refocus": "special_cases",
    "recover_plane_texture": "special_cases",
    "DeconvolutionParams": "deconvolution",
    # blind deblurring
    "blind_deblur": "blind",
    "iter_blind_deblur": "blind",
    "BlindParams": "blind",
    "BlindResult": "blind",
    # metrics
    "psnr": "metrics",
    "ssim": "metrics",
    "path_error": "metrics",
    "angular_error": "metrics",
    # many light fields on dask.distributed
    "simulate_dataset": "batch",
    "deblur_many": "batch",
    # devices
    "select_device": "devices",
    # solver progress records
    "Progress": "progress",
    "run_to_completion": "progress",
    "with_previews": "progress",
}

__all__ = ["__version__", *_PUBLIC]


def __getattr__(name: str):
    module = _PUBLIC.get(name)
    if module is None:
        raise AttributeError(f"module 'napari_lfdeblur' has no attribute {name!r}")
    value = getattr(importlib.import_module(f".{module}", __name__), name)
    globals()[name] = value
    return value


def __dir__():
    return sorted(__all__)
