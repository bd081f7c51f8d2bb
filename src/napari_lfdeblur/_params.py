"""The dict and JSON round trips shared by the solvers' frozen parameter dataclasses."""

from __future__ import annotations

import json
from dataclasses import asdict, fields, replace


class JsonParams:
    """Mixin of a frozen parameter dataclass: :meth:`to_json` / :meth:`from_json` presets.

    A subclass names what it parameterises in ``_what`` (used in error
    messages). Unknown keys are an error, never silently dropped; the
    dataclass's own ``__post_init__`` checks the values.
    """

    _what = "solver"

    @classmethod
    def _check_keys(cls, d) -> None:
        known = {f.name for f in fields(cls)}
        unknown = sorted(set(d) - known)
        if unknown:
            raise ValueError(
                f"unknown {cls._what} parameter(s): {', '.join(map(str, unknown))}; "
                f"known: {', '.join(sorted(known))}"
            )

    def replace(self, **changes):
        """A copy with some fields changed (checked like the constructor)."""
        self._check_keys(changes)
        return replace(self, **changes)

    def to_dict(self) -> dict:
        """The parameters as a plain dict (JSON types only)."""
        return asdict(self)

    @classmethod
    def from_dict(cls, d: dict):
        """Parameters from a dict; missing keys take the default, unknown keys are an error."""
        if not isinstance(d, dict):
            raise ValueError(f"{cls.__name__}.from_dict needs a dict; got {type(d).__name__}")
        cls._check_keys(d)
        return cls(**d)

    def to_json(self) -> str:
        """The parameters as a JSON text."""
        return json.dumps(self.to_dict(), indent=2)

    @classmethod
    def from_json(cls, text: str):
        """Parameters from a JSON text written by :meth:`to_json`."""
        try:
            d = json.loads(text)
        except (json.JSONDecodeError, TypeError) as exc:
            raise ValueError(f"invalid JSON for {cls.__name__}: {exc}") from None
        return cls.from_dict(d)
