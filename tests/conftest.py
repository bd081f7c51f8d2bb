"""Shared test settings."""

from pathlib import Path

import pytest

#: the real Lytro capture in the shared data folder beside the repository
LYTRO_DIR = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "lytro-f01-img0001"


@pytest.fixture
def notifications(monkeypatch):
    """Messages shown through the napari widgets' notification helpers (needs napari)."""
    from napari_lfdeblur._napari.widgets import _controls

    seen = []
    monkeypatch.setattr(_controls, "show_error", lambda msg: seen.append(("error", msg)))
    monkeypatch.setattr(_controls, "show_info", lambda msg: seen.append(("info", msg)))
    monkeypatch.setattr(_controls, "show_warning", lambda msg: seen.append(("warning", msg)))
    return seen


@pytest.fixture(params=["fused", "torch"])
def engine(request, monkeypatch):
    """Runs a test with the blur's fused CPU loops (numba) and again with its torch version.

    The fused loops' tiles of a rotation's kernel are 16 px here (128 by default), so that the small light
    fields of the tests span several tiles with either version.
    """
    from napari_lfdeblur import _fused, _taps_tiled

    if request.param == "fused" and not _fused.available("cpu"):
        pytest.skip("numba is not installed")
    monkeypatch.setattr(_taps_tiled, "FUSED_TILE_SIDE", 16)
    if request.param == "torch":
        monkeypatch.setattr(_fused, "available", lambda *args: False)
    return request.param


def wrap_prox_inner_iteration(monkeypatch, wrapper):
    """Replaces what each inner iteration of the TV prox calls once by ``wrapper(real, *args, **kwargs)``.

    That is the fused sweep where the fused loops run (the TV along the views' or along the disparity's), the torch
    version's dual projection otherwise.
    """
    from napari_lfdeblur import _fused, _tv_solvers

    if _fused.available("cpu"):
        from napari_lfdeblur import _oriented_loops

        targets = [(_fused, "prox_sweep"), (_oriented_loops, "prox_sweep")]
    else:
        targets = [(_tv_solvers, "project_tv_dual")]
    for module, name in targets:
        real = getattr(module, name)
        monkeypatch.setattr(module, name, lambda *args, real=real, **kwargs: wrapper(real, *args, **kwargs))
