"""The dict and JSON round trips shared by the solvers' frozen parameter dataclasses.

A field whose default is itself a :class:`JsonParams` instance is *nested*:
it is written as a sub-dict by :meth:`JsonParams.to_dict`, and a sub-dict
given to :meth:`JsonParams.from_dict` or :meth:`JsonParams.replace` is
merged onto the field's default (``from_dict``) or its current value
(``replace``). A nested field may also be None where the dataclass allows it.
"""

from __future__ import annotations

import contextlib
import dataclasses
import json
import math
from dataclasses import MISSING, asdict, fields

import numpy as np

__all__ = ["JsonParams", "check_int", "check_float", "check_bool", "check_fields"]


class JsonParams:
    """Mixin of a frozen parameter dataclass: :meth:`to_json` / :meth:`from_json` presets.

    A subclass names what it parameterises in ``_what`` (used in error
    messages). Unknown keys are an error, never silently dropped: a
    :class:`ValueError` in :meth:`from_dict` / :meth:`from_json` (bad data), a
    :class:`TypeError` in :meth:`replace` (a bad keyword argument). The
    dataclass's own ``__post_init__`` checks the values.
    """

    _what = "solver"

    @classmethod
    def _nested_defaults(cls) -> dict:
        """``{name: default}`` of the fields whose default is a :class:`JsonParams`."""
        out = {}
        for f in fields(cls):
            if f.default is not MISSING:
                default = f.default
            elif f.default_factory is not MISSING:
                default = f.default_factory()
            else:
                continue
            if isinstance(default, JsonParams):
                out[f.name] = default
        return out

    @classmethod
    def _unknown_message(cls, keys) -> str | None:
        known = {f.name for f in fields(cls)}
        unknown = sorted(set(keys) - known, key=str)
        if not unknown:
            return None
        return (
            f"unknown {cls._what} parameter(s): {', '.join(map(str, unknown))}; "
            f"known: {', '.join(sorted(known))}"
        )

    @classmethod
    def _check_keys(cls, d) -> None:
        """ValueError on keys of ``d`` that are not fields."""
        message = cls._unknown_message(d)
        if message:
            raise ValueError(message)

    def replace(self, **changes):
        """A copy with some fields changed (checked like the constructor).

        A nested field takes an instance, or a dict of its fields merged into
        its current value (into its default when it is None).

        Raises
        ------
        TypeError
            On an unknown field name (here or in a nested dict).
        """
        message = self._unknown_message(changes)
        if message:
            raise TypeError(message)
        nested = self._nested_defaults()
        for name, value in changes.items():
            if name in nested and isinstance(value, dict):
                current = getattr(self, name)
                with self._naming(name):
                    changes[name] = (nested[name] if current is None else current).replace(**value)
        return dataclasses.replace(self, **changes)

    @classmethod
    @contextlib.contextmanager
    def _naming(cls, name):
        """Errors of the nested field ``name`` say which field they are about (``BlindParams.final: ...``)."""
        where = f"{cls.__name__}.{name}"
        try:
            yield
        except (TypeError, ValueError) as exc:
            if where in str(exc):
                raise
            raise type(exc)(f"{where}: {exc}") from None

    def to_dict(self) -> dict:
        """The parameters as a plain dict (JSON types only; nested fields as sub-dicts)."""
        d = asdict(self)
        for name in self._nested_defaults():
            value = getattr(self, name)
            d[name] = None if value is None else value.to_dict()
        return d

    @classmethod
    def from_dict(cls, d: dict):
        """Parameters from a dict; missing keys take the default, unknown keys are an error.

        A sub-dict of a nested field is merged onto that field's default.

        Raises
        ------
        ValueError
            On unknown keys (here or in a sub-dict) and invalid values.
        TypeError
            If ``d`` is not a dict, or a value has the wrong type.
        """
        if not isinstance(d, dict):
            raise TypeError(f"{cls.__name__}.from_dict needs a dict; got {type(d).__name__}")
        cls._check_keys(d)
        d = dict(d)
        for name, default in cls._nested_defaults().items():
            value = d.get(name)
            if isinstance(value, dict):
                sub = type(default)
                with cls._naming(name):
                    sub._check_keys(value)
                    d[name] = sub.from_dict({**default.to_dict(), **value})
        return cls(**d)

    def to_json(self) -> str:
        """The parameters as a JSON text."""
        return json.dumps(self.to_dict(), indent=2)

    @classmethod
    def from_metadata(cls, metadata: dict):
        """The parameters a result was made with, from its metadata.

        ``metadata`` is a result layer's ``metadata`` in napari, a result
        file's (``read_lightfield_with_metadata(path)[1]``, which holds it
        under ``'saved_metadata'``; a batch run's item too), or that saved
        dict itself. Its ``'parameters'`` stamp holds every field, as
        :meth:`to_dict` writes them, next to the run's settings (seed,
        device, ``d_inf``, the weight used, ...), which are left out here:
        pass them to the solver as they are.

        Raises
        ------
        ValueError
            When there is no ``'parameters'`` dict, or it lacks a field (it
            is another solver's), or a value is invalid.
        """
        if isinstance(metadata, dict) and "parameters" not in metadata:
            metadata = metadata.get("saved_metadata", metadata)  # a file's, as read back
        if isinstance(metadata, dict) and "parameters" not in metadata and isinstance(metadata.get("batch"), dict):
            metadata = {"parameters": (metadata["batch"].get("parameters") or {}).get("params")}  # a batch item's
        stamp = metadata.get("parameters") if isinstance(metadata, dict) else None
        if not isinstance(stamp, dict):
            raise ValueError(f"{cls.__name__}.from_metadata needs a result's metadata, with a 'parameters' dict")
        names = [f.name for f in fields(cls)]
        missing = [n for n in names if n not in stamp]
        if missing:
            raise ValueError(f"the metadata's parameters are not {cls.__name__}'s: they lack {', '.join(missing)}")
        return cls.from_dict({n: stamp[n] for n in names})

    @classmethod
    def from_json(cls, text: str):
        """Parameters from a JSON text written by :meth:`to_json` (a ValueError on bad text)."""
        try:
            d = json.loads(text)
        except (json.JSONDecodeError, TypeError) as exc:
            raise ValueError(f"invalid JSON for {cls.__name__}: {exc}") from None
        if not isinstance(d, dict):
            raise ValueError(f"{cls.__name__}.from_json needs a dict (a JSON object); got {type(d).__name__}")
        return cls.from_dict(d)


def check_int(obj, name: str, lo: int, label: str) -> None:
    """Check that ``obj.<name>`` is an integer >= ``lo`` and store it as ``int``.

    Raises TypeError for a non-integer (bools included), ValueError below
    ``lo``; ``label`` names the field in the messages.
    """
    v = getattr(obj, name)
    if isinstance(v, bool) or not isinstance(v, (int, np.integer)):
        raise TypeError(f"{label} must be an integer >= {lo}; got {v!r}")
    if v < lo:
        raise ValueError(f"{label} must be >= {lo}; got {v}")
    object.__setattr__(obj, name, int(v))


def check_float(obj, name: str, kind: str, label: str) -> None:
    """Check that ``obj.<name>`` is a finite number of ``kind`` and store it as ``float``.

    ``kind``: ``'signed'`` (any finite number), ``'nonneg'`` (>= 0) or
    ``'positive'`` (> 0). Raises TypeError for a non-number (bools and
    strings included), ValueError for a value out of range.
    """
    v = getattr(obj, name)
    if isinstance(v, bool) or not isinstance(v, (int, float, np.integer, np.floating)):
        raise TypeError(f"{label} must be a number; got {v!r}")
    v = float(v)
    bad = not math.isfinite(v) or (kind != "signed" and v < 0) or (kind == "positive" and v == 0)
    if bad:
        what = {"positive": "> 0", "nonneg": ">= 0", "signed": "a number"}[kind]
        raise ValueError(f"{label} must be finite and {what}; got {v!r}")
    object.__setattr__(obj, name, v)


def check_bool(obj, name: str, label: str) -> None:
    """Check that ``obj.<name>`` is a bool (Python's or numpy's) and store it as ``bool``.

    Raises TypeError for anything else: the strings ``"false"`` or ``"0"``
    (true as Python truth values) and the numbers 0 and 1 included.
    """
    v = getattr(obj, name)
    if not isinstance(v, (bool, np.bool_)):
        raise TypeError(f"{label} must be true or false; got {v!r}")
    object.__setattr__(obj, name, bool(v))


def check_fields(obj, prefix: str, ints=None, nonneg=(), positive=(), signed=(), unit=(), bools=()) -> None:
    """Check the fields of a parameter dataclass (see :func:`check_int`, :func:`check_float`).

    ``unit`` fields must be in (0, 1] (they are also in ``positive``).
    """
    for name, lo in (ints or {}).items():
        check_int(obj, name, lo, f"{prefix}.{name}")
    for kind, names in (("nonneg", nonneg), ("positive", positive), ("signed", signed)):
        for name in names:
            check_float(obj, name, kind, f"{prefix}.{name}")
    for name in unit:
        if getattr(obj, name) > 1:
            raise ValueError(f"{prefix}.{name} must be in (0, 1]; got {getattr(obj, name)}")
    for name in bools:
        check_bool(obj, name, f"{prefix}.{name}")
