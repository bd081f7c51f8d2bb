"""The argument types of the ``lfdeblur`` command's options: each parses one option's text or raises
:class:`argparse.ArgumentTypeError`, which argparse prints as one line."""

from __future__ import annotations

import argparse
import math

from ._lightfield import check_seed

__all__ = ["angular_crop", "fraction", "gib", "seed", "value_range", "view_grid", "window"]


def _whole_numbers(text: str) -> tuple:
    """``A,B,...`` (or ``AxB``) as a tuple of ints; ``()`` when a part is not one."""
    try:
        return tuple(int(n) for n in text.replace("x", ",").split(","))
    except ValueError:
        return ()


def angular_crop(text: str):
    """``--angular-crop``: ``N`` or ``NV,NU``."""
    sizes = _whole_numbers(text)
    if len(sizes) not in (1, 2):
        raise argparse.ArgumentTypeError(f"{text!r}: expected N or NV,NU such as 9 or 9,9")
    return sizes[0] if len(sizes) == 1 else sizes


def fraction(text: str) -> float:
    """A number in [0, 1] (``--light-restoration``)."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r}: expected a number in [0, 1], such as 0.5") from None
    if not 0.0 <= value <= 1.0:
        raise argparse.ArgumentTypeError(f"{text!r}: expected a number in [0, 1], such as 0.5")
    return value


def gib(text: str) -> int:
    """A positive number of GiB, as bytes (``--max-memory``)."""
    try:
        value = float(text)
    except ValueError:
        value = float("nan")
    if not math.isfinite(value) or value <= 0:
        raise argparse.ArgumentTypeError(f"{text!r}: expected a positive number of GiB, such as 4 or 1.5")
    return int(value * 2**30)


def view_grid(text: str) -> tuple:
    """``--grid``: ``V,U`` (or ``VxU``), the views of a mosaic."""
    sizes = _whole_numbers(text)
    if len(sizes) != 2 or min(sizes) < 1:
        raise argparse.ArgumentTypeError(f"{text!r}: expected V,U such as 9,9")
    return sizes


def seed(text: str) -> int:
    """``--seed``: a whole number from 0 to :data:`~napari_lfdeblur._lightfield.MAX_SEED` (:func:`check_seed`)."""
    try:
        return check_seed(int(text))
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r}: expected a whole number from 0 to 2**63 - 1") from None


def value_range(text: str):
    """``--value-range``: ``LO,HI`` or ``auto`` (:func:`napari_lfdeblur.io.parse_value_range`)."""
    from .io import parse_value_range

    try:
        return parse_value_range(text)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def window(text: str) -> tuple:
    """``--window``: ``Y0,X0,H,W``, a window of the view in pixels (checked against the views by the solver)."""
    try:
        values = tuple(int(n) for n in text.split(","))
    except ValueError:
        values = ()
    if len(values) != 4 or min(values) < 0:
        raise argparse.ArgumentTypeError(f"{text!r}: expected Y0,X0,HEIGHT,WIDTH in pixels, such as 0,0,128,128")
    return values
