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
