"""The manifest (``manifest.jsonl``) and the dataset card (``README.md``) of an output folder.

Only the client writes them. The manifest is appended one JSON line per
finished item and flushed to disk line by line; a line cut short by a kill is
ignored when read. The card is replaced atomically.
"""

from __future__ import annotations

import json
import os
from contextlib import contextmanager
from pathlib import Path

__all__ = ["MANIFEST", "CARD", "read_manifest", "open_manifest", "append_record", "write_card", "check_card"]

MANIFEST = "manifest.jsonl"
CARD = "README.md"
_CARD_TITLE = "# Light-field dataset made by napari-lfdeblur batch"


def read_manifest(out_dir) -> dict[str, dict]:
    """The last record of each output in ``out_dir/manifest.jsonl`` (``{output name: record}``).

    Lines that are not complete JSON objects (a run killed while writing one)
    are skipped.
    """
    path = Path(out_dir) / MANIFEST
    last = {}
    if not path.is_file():
        return last
    with open(path, encoding="utf-8") as fh:
        for line in fh:
            try:
                rec = json.loads(line)
            except json.JSONDecodeError:
                continue
            if isinstance(rec, dict) and isinstance(rec.get("output"), str):
                last[rec["output"]] = rec
    return last


@contextmanager
def open_manifest(out_dir):
    """The manifest opened for appending, locked against a second run in the same folder.

    Raises
    ------
    RuntimeError
        When another process holds the lock (where locks are available).
    """
    path = Path(out_dir) / MANIFEST
    with open(path, "a+", encoding="utf-8") as fh:
        try:
            import fcntl
        except ImportError:  # not POSIX: no lock
            fcntl = None
        if fcntl is not None:
            try:
                fcntl.flock(fh.fileno(), fcntl.LOCK_EX | fcntl.LOCK_NB)
            except OSError:
                raise RuntimeError(f"another run is writing to {out_dir} (its {MANIFEST} is locked)") from None
        fh.seek(0, os.SEEK_END)
        if fh.tell() > 0:  # end a line cut short by a killed run
            fh.seek(fh.tell() - 1)
            if fh.read(1) != "\n":
                fh.write("\n")
        yield fh


def append_record(fh, record: dict) -> None:
    """Append one record as a JSON line and push it to disk."""
    fh.write(json.dumps(record, sort_keys=True) + "\n")
    fh.flush()
    os.fsync(fh.fileno())


def check_card(out_dir) -> None:
    """Raise FileExistsError when ``out_dir/README.md`` exists and is not a dataset card of ours."""
    path = Path(out_dir) / CARD
    if path.is_file() and not path.read_text(encoding="utf-8", errors="replace").startswith(_CARD_TITLE):
        raise FileExistsError(f"{path} exists and is not a dataset card written by napari-lfdeblur; "
                              "choose another output folder")


def write_card(out_dir, *, kind: str, command: str, parameters: dict, seed: int, version: str,
               counts: dict | None = None) -> Path:
    """Write the dataset card: what the folder holds and the command that makes it again."""
    what = {
        "simulate": "light fields blurred by random camera paths (the forward model of napari-lfdeblur, "
                    "docs/model.md); the sharp light field of each item is its input",
        "deblur": "light fields deblurred blindly (napari_lfdeblur.blind.blind_deblur), with their estimated "
                  "camera paths",
    }[kind]
    lines = [
        _CARD_TITLE, "",
        f"This folder holds {what}.", "",
        "## How to make it again", "",
        "```bash" if not command.startswith(("import", "from")) else "```python",
        command, "```", "",
        f"napari-lfdeblur {version}; run seed {seed}. Items are deterministic: item `index` of the input named "
        "`name` uses the seed `napari_lfdeblur.batch.item_seed(seed, name, index)`.", "",
        "## Parameters", "", "```json", json.dumps(parameters, indent=2, sort_keys=True), "```", "",
        "## Layout", "",
        "- `<name>_<index>.npz` (simulate) or `<name>.npz` (deblur): the light field, float32, axes "
        "`(V, U, Y, X[, C])`; read it with `napari_lfdeblur.read_lightfield`.",
        "- `<output stem>.path.json`: its camera path (Bezier control points).",
        f"- `{MANIFEST}`: one JSON line per finished item (input, output, parameters, seed, version, status, "
        "time, error, size); the last line of an output is the one that counts.",
    ]
    if counts:
        lines += ["", "## Last run", "", ", ".join(f"{v} {k}" for k, v in counts.items()) + "."]
    path = Path(out_dir) / CARD
    tmp = path.with_name(f".{CARD}.tmp{os.getpid()}")
    tmp.write_text("\n".join(lines) + "\n", encoding="utf-8")
    os.replace(tmp, path)
    return path
