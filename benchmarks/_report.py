"""Shared helpers of the benchmark scripts: the machine description and the table file.

Every user-facing script in ``benchmarks/`` writes its table to
``docs/benchmarks/<script>.md`` (or to ``--out``), overwriting it. The file
holds a heading, the command that produced it, the machine it ran on and the
table itself, and nothing else about how or when it was made.
"""

from __future__ import annotations

import argparse
import os
import platform
import shlex
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
TABLES = ROOT / "docs" / "benchmarks"

__all__ = ["ROOT", "TABLES", "add_out_argument", "command_line", "cpu_model", "default_table", "exit_status",
           "machine", "table_path", "write_table"]


def cpu_model() -> str:
    """The CPU's model name (from ``/proc/cpuinfo`` on Linux), else what ``platform`` knows."""
    try:
        with open("/proc/cpuinfo") as fh:
            for line in fh:
                if line.lower().startswith("model name"):
                    return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine()


def machine(device: str | None = None) -> str:
    """One line describing the machine: CPU model and cores, torch version and threads, device.

    Parameters
    ----------
    device : str, optional
        The torch device the benchmark ran on (``'cpu'``, ``'cuda'``, ``'cuda:0'``; ``'auto'``:
        the one the package's ``device='auto'`` picks); a CUDA device is named by its model.
    """
    import torch

    if device == "auto":
        from napari_lfdeblur.devices import select_device

        device = select_device("auto").type

    text = (f"{cpu_model()}, {os.cpu_count()} cores; torch {torch.__version__}, "
            f"{torch.get_num_threads()} threads")
    if device is not None:
        dev = str(device)
        if dev.startswith("cuda") and torch.cuda.is_available():
            dev = f"{dev} ({torch.cuda.get_device_name(torch.device(dev))})"
        text += f"; device {dev}"
    return text


def command_line(script: str | Path, argv=None) -> str:
    """The command that ran ``script`` with ``argv`` (default: this process's arguments)."""
    argv = sys.argv[1:] if argv is None else list(argv)
    rel = Path(script).resolve()
    try:
        rel = rel.relative_to(ROOT)
    except ValueError:
        pass
    return " ".join(["python", shlex.quote(str(rel)), *map(shlex.quote, map(str, argv))])


def default_table(script: str | Path) -> Path:
    """``docs/benchmarks/<script>.md``: where ``script`` writes its table by default."""
    return TABLES / f"{Path(script).stem}.md"


def add_out_argument(parser: argparse.ArgumentParser, script: str | Path, *option_strings: str) -> None:
    """Add ``--out PATH`` to ``parser`` (default: None, resolved by :func:`table_path`)."""
    parser.add_argument("--out", *option_strings, type=Path, default=None, metavar="PATH",
                        help=f"markdown file to write the table to (default "
                             f"{default_table(script).relative_to(ROOT)}; none for a smoke run)")


def table_path(out: Path | None, script: str | Path, smoke: bool = False) -> Path | None:
    """Where to write: ``out`` when given, else the default table, or nowhere for a smoke run."""
    if out is not None:
        return Path(out)
    return None if smoke else default_table(script)


def write_table(path: str | Path, title: str, command: str, machine_line: str, body: list[str]) -> Path:
    """Write a table file: a heading, the command, the machine, then ``body`` (markdown lines).

    The file is replaced as a whole; its folder is created when missing.
    """
    path = Path(path)
    lines = [f"# {title}", "", f"Command: `{command}`", "", f"Machine: {machine_line}", "", *body]
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text("\n".join(lines).rstrip("\n") + "\n")
    print(f"wrote {path}", file=sys.stderr)
    return path


def exit_status(failed: list[str]) -> int:
    """The exit status of a script whose runs ``failed`` (their names): 0 when none did, else 1, said on stderr.

    A script with failed runs leaves its table as it was: a table without
    them would pass for a complete one.
    """
    if not failed:
        return 0
    print(f"{len(failed)} run(s) failed ({', '.join(failed)}): no table written", file=sys.stderr)
    return 1
