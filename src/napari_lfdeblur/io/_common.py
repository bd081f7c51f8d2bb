"""Shared helpers of the light-field readers and writers: errors, conversion
to float32 in [0, 1], the memory check and atomic writes.

Nothing here imports napari or Qt.
"""

from __future__ import annotations

import functools
import operator
import os
import shutil
import uuid
import warnings
from contextlib import contextmanager
from pathlib import Path

import numpy as np

from .._lightfield import validate_lightfield as check_lightfield

from .._memory import host_available_memory

__all__ = [
    "LightFieldError",
    "LightFieldFormatError",
    "LightFieldReadError",
    "names_the_file",
    "InsufficientMemoryError",
    "MEMORY_LIMIT_ENV",
    "available_memory",
    "check_memory",
    "central_views",
    "to_float01",
    "parse_value_range",
    "check_value_range",
    "RESCALE_HINT",
    "validate_lightfield",
    "atomic_file",
    "atomic_dir",
    "temporary_name",
]

#: Environment variable that caps the memory a read may use, in bytes.
MEMORY_LIMIT_ENV = "LFDEBLUR_MEMORY_LIMIT"


class LightFieldError(ValueError):
    """A file or array is not a light field we can read or write."""


class LightFieldFormatError(LightFieldError):
    """The data is readable but its layout is wrong (missing view, mixed sizes,
    wrong number of dimensions, NaN, ...)."""


class LightFieldReadError(LightFieldError, OSError):
    """A file could not be decoded: truncated, corrupt, or not an image at all."""


def names_the_file(what: str):
    """Decorator of a reader ``f(path, ...)``: an error of the decoding library inside it (anything but a
    :class:`LightFieldError`, a ``MemoryError`` or an interrupt) becomes one :class:`LightFieldReadError`
    that names the file, ``"<path>: <what> (<error>)"``; a corrupt HDF5 file fails in many places."""
    def wrap(reader):
        @functools.wraps(reader)
        def read(path, *args, **kwargs):
            try:
                return reader(path, *args, **kwargs)
            except (LightFieldError, MemoryError):
                raise
            except Exception as exc:  # noqa: BLE001 - whatever the library raised
                raise LightFieldReadError(f"{path}: {what} ({type(exc).__name__}: {exc})") from None
        return read
    return wrap


class InsufficientMemoryError(LightFieldError, MemoryError):
    """Decoding the file would need more memory than is available."""


# ----------------------------------------------------------------- memory


def available_memory() -> int:
    """Bytes of memory a read may use.

    The value of the environment variable ``LFDEBLUR_MEMORY_LIMIT`` (bytes)
    when set, else the available system memory (``psutil`` or
    ``/proc/meminfo``). Returns a very large number when neither is known.
    """
    env = os.environ.get(MEMORY_LIMIT_ENV)
    if env:
        try:
            return int(float(env))
        except ValueError:
            raise ValueError(f"{MEMORY_LIMIT_ENV}={env!r} is not a number of bytes") from None
    available = host_available_memory()
    return (1 << 62) if available is None else available


def _fmt_bytes(n: float) -> str:
    for unit in ("B", "KiB", "MiB", "GiB", "TiB"):
        if abs(n) < 1024 or unit == "TiB":
            return f"{n:.1f} {unit}" if unit != "B" else f"{int(n)} B"
        n /= 1024
    return f"{n:.1f} TiB"  # pragma: no cover


def check_memory(shape, source_itemsize: int, path, *, max_bytes=None, out_shape=None) -> int:
    """Raise before allocating if decoding ``shape`` would not fit in memory.

    Parameters
    ----------
    shape : tuple of int
        Shape of the data read from the file.
    source_itemsize : int
        Bytes per element of the data as stored (the float32 result needs 4
        more per element, unless the source is float32 already).
    path : str or Path
        The file, for the message.
    max_bytes : int, optional
        Limit in bytes; default :func:`available_memory`.
    out_shape : tuple of int, optional
        Shape of the float32 result when it is smaller than what is read (a
        file read whole and then cropped to its central views); default
        ``shape``.

    Returns
    -------
    int
        The estimated number of bytes.
    """
    n = int(np.prod([int(s) for s in shape], dtype=np.float64))
    n_out = n if out_shape is None else int(np.prod([int(s) for s in out_shape], dtype=np.float64))
    need = n * int(source_itemsize) + n_out * 4
    limit = available_memory() if max_bytes is None else int(max_bytes)
    if need > limit:
        raise InsufficientMemoryError(
            f"{path}: decoding a light field of shape {tuple(int(s) for s in shape)} needs about "
            f"{_fmt_bytes(need)} but only {_fmt_bytes(limit)} is available; crop or downsample "
            f"it first, or read it on a machine with more memory"
        )
    return need


def central_views(V: int, U: int, angular_crop, path) -> tuple[slice, slice]:
    """The central views that ``angular_crop`` keeps of a ``V x U`` grid, as two slices.

    ``angular_crop`` is ``n`` (keep ``n x n`` views) or ``(n_v, n_u)``. The
    kept block starts at view ``(V - n_v) // 2``, ``(U - n_u) // 2``.

    Raises
    ------
    LightFieldFormatError
        When a size is not an integer between 1 and the grid's (a
        ValueError, and a :class:`LightFieldError`, which the readers'
        :func:`names_the_file` passes on as it is: the file is readable).
    """
    try:
        n_v, n_u = (angular_crop, angular_crop) if np.ndim(angular_crop) == 0 else angular_crop
        ok = not any(isinstance(n, bool) for n in (n_v, n_u))
        n_v, n_u = operator.index(n_v), operator.index(n_u)  # integers only
    except (TypeError, ValueError):
        ok = False
    if not ok or not (1 <= n_v <= V and 1 <= n_u <= U):
        raise LightFieldFormatError(
            f"{path}: angular_crop={angular_crop!r} must be n or (n_v, n_u) with 1 <= n_v <= {V} and "
            f"1 <= n_u <= {U} (the file has {V} x {U} views)"
        )
    v0, u0 = (V - n_v) // 2, (U - n_u) // 2
    return slice(v0, v0 + n_v), slice(u0, u0 + n_u)


# ----------------------------------------------------------------- values


#: How to name the rescaling in messages: the argument, the command line's option and the widget's field.
RESCALE_HINT = ("value_range=(lo, hi) (e.g. (0, 4095) for 12-bit data) or value_range='auto' (command line: "
                "--value-range LO,HI or --value-range auto; napari: the Open light field widget's value range)")


def parse_value_range(text):
    """A ``value_range`` from text: ``''`` (None: as stored), ``'auto'``, or ``'LO,HI'`` (two numbers, ``LO < HI``).

    Returns
    -------
    None, 'auto' or tuple of 2 float

    Raises
    ------
    ValueError
        On anything else, with an example of what is expected.

    Examples
    --------
    >>> parse_value_range("0,4095")
    (0.0, 4095.0)
    """
    text = "" if text is None else str(text).strip()
    if text == "":
        return None
    if text.lower() == "auto":
        return "auto"
    try:
        return check_value_range(tuple(float(v) for v in text.split(",")))
    except ValueError:
        raise ValueError(f"value range {text!r}: expected LO,HI with LO < HI, such as 0,4095, or auto") from None


def check_value_range(value_range):
    """``value_range`` as None, ``'auto'`` or ``(lo, hi)`` floats; ``ValueError`` unless finite with ``lo < hi``."""
    if value_range is None or (isinstance(value_range, str) and value_range == "auto"):
        return value_range
    try:
        lo, hi = (float(v) for v in value_range)
    except (TypeError, ValueError):
        raise ValueError(f"value_range must be (lo, hi) or 'auto', not {value_range!r}") from None
    if not (np.isfinite(lo) and np.isfinite(hi) and lo < hi):
        raise ValueError(f"value_range (lo, hi) must be finite with lo < hi; got {value_range!r}")
    return lo, hi


def to_float01(arr, path, *, value_range=None) -> np.ndarray:
    """Convert an array to float32 in [0, 1].

    Integer data is divided by its dtype's maximum. Float data must already
    lie in [0, 1] (overshoots of up to 1e-3 from rounding are clipped), unless
    ``value_range=(lo, hi)`` maps ``lo`` to 0 and ``hi`` to 1, or
    ``value_range='auto'`` uses the data's own minimum and maximum (constant
    data is read as 0, with a warning).

    Raises
    ------
    LightFieldFormatError
        On NaN or Inf, on a non-numeric dtype, or on float data outside
        [0, 1] without a ``value_range``.
    ValueError
        On a ``value_range`` that is neither ``'auto'`` nor finite ``(lo, hi)``
        with ``lo < hi``.
    """
    value_range = check_value_range(value_range)
    arr = np.asarray(arr)
    if arr.dtype == bool:
        return arr.astype(np.float32)
    if arr.dtype.kind not in "iuf":  # (numpy counts timedelta64 as an integer)
        raise LightFieldFormatError(f"{path}: unsupported data type {arr.dtype}; expected integers or floats")
    if value_range is None and np.issubdtype(arr.dtype, np.integer):
        info = np.iinfo(arr.dtype)
        if info.min < 0 and arr.size and arr.min() < 0:
            raise LightFieldFormatError(
                f"{path}: signed integer data has negative values; pass {RESCALE_HINT}"
            )
        out = arr.astype(np.float32)
        out /= np.float32(info.max)  # divide (not multiply by 1/max): exact for every integer value
        return out
    if arr.size and not np.isfinite(arr).all():
        bad = int(np.count_nonzero(~np.isfinite(arr)))
        raise LightFieldFormatError(f"{path}: the data contains {bad} NaN or Inf value(s)")
    if arr.size == 0:
        raise LightFieldFormatError(f"{path}: the light field is empty (shape {arr.shape})")
    if value_range is not None:
        lo, hi = (float(arr.min()), float(arr.max())) if value_range == "auto" else value_range
        if not hi > lo:  # 'auto' on constant data
            warnings.warn(f"{path}: every value is {lo:.6g}, so value_range='auto' has no range to stretch; it is "
                          "read as 0 everywhere (give value_range=(lo, hi) to read it on a scale)", stacklevel=2)
            hi = lo + 1.0
        if arr.dtype.itemsize > 4:  # float64 and wider: scaled first (values may lie beyond float32's range)
            out = ((arr - lo) * (1.0 / (hi - lo))).astype(np.float32)
        else:
            out = (arr.astype(np.float32, copy=False) - np.float32(lo)) * np.float32(1.0 / (hi - lo))
        np.clip(out, 0.0, 1.0, out=out)
        return out
    lo, hi = float(arr.min()), float(arr.max())
    if lo < -1e-3 or hi > 1.0 + 1e-3:
        raise LightFieldFormatError(
            f"{path}: float values span [{lo:.4g}, {hi:.4g}], outside [0, 1]; to rescale, pass {RESCALE_HINT}"
        )
    out = arr.astype(np.float32, copy=arr.dtype != np.float32)
    if lo < 0 or hi > 1:
        np.clip(out, 0.0, 1.0, out=out)
    return out


def validate_lightfield(lf, path="light field") -> np.ndarray:
    """The light field check of :func:`napari_lfdeblur._lightfield.validate_lightfield` for a file's array.

    The same rules; a failure is a :class:`LightFieldFormatError` that names
    ``path``, and a trailing channel axis of length 1 is dropped. NaN and Inf
    are left to :func:`to_float01`, which counts them.
    """
    try:
        lf = check_lightfield(lf, "light field", finite=False)  # the message then names the file
    except ValueError as exc:
        raise LightFieldFormatError(f"{path}: {exc}") from None
    return lf[..., 0] if lf.ndim == 5 and lf.shape[-1] == 1 else lf


# ----------------------------------------------------------------- atomic writes


def temporary_name(path: Path, suffix: str = "") -> Path:
    """A hidden name beside ``path``, unique to this process and call, for a file written and then renamed."""
    return path.with_name(f".{path.name}.tmp{os.getpid()}-{uuid.uuid4().hex[:8]}{suffix}")


def check_writable(path: Path, overwrite: bool) -> None:
    """Raise FileExistsError unless ``path`` is free or ``overwrite`` is set."""
    if path.exists() and not overwrite:
        raise FileExistsError(f"{path} exists; pass overwrite=True to replace it")
    if not path.parent.exists():
        raise FileNotFoundError(f"cannot write {path}: the folder {path.parent} does not exist")


@contextmanager
def atomic_file(path, *, overwrite=False):
    """Yield a temporary path next to ``path``; rename it to ``path`` on success.

    On any error the temporary file is removed and ``path`` is untouched.
    The temporary name keeps the suffix of ``path`` (some writers need it).
    """
    path = Path(path)
    check_writable(path, overwrite)
    if path.is_dir():
        raise IsADirectoryError(f"cannot write {path}: it is a folder")
    tmp = temporary_name(path, path.suffix)
    try:
        yield tmp
        if path.exists() and not overwrite:  # appeared meanwhile
            raise FileExistsError(f"{path} exists; pass overwrite=True to replace it")
        os.replace(tmp, path)
    finally:
        if tmp.exists():
            tmp.unlink()


@contextmanager
def atomic_dir(path, *, overwrite=False, replaceable=None):
    """Yield a temporary folder next to ``path``; move it to ``path`` on success.

    An existing folder is replaced only if ``overwrite`` and every entry in it
    satisfies ``replaceable(name)`` (so that a user's other files are never
    deleted). On error the temporary folder is removed.
    """
    path = Path(path)
    check_writable(path, overwrite)
    if path.exists():
        if not path.is_dir():
            raise FileExistsError(f"cannot write views to {path}: a file of that name exists")
        foreign = [p.name for p in path.iterdir() if replaceable is None or not replaceable(p.name)]
        if foreign:
            raise FileExistsError(
                f"{path} contains files that are not light-field views ({', '.join(sorted(foreign)[:3])}"
                f"{', ...' if len(foreign) > 3 else ''}); refusing to replace it, choose another folder"
            )
    tmp = temporary_name(path)
    old = temporary_name(path, ".old")
    if tmp.exists():
        shutil.rmtree(tmp)
    tmp.mkdir()
    try:
        yield tmp
        if path.exists():
            os.replace(path, old)
            try:
                os.replace(tmp, path)
            except BaseException:
                os.replace(old, path)
                raise
            shutil.rmtree(old, ignore_errors=True)
        else:
            os.replace(tmp, path)
    finally:
        if tmp.exists():
            shutil.rmtree(tmp, ignore_errors=True)
