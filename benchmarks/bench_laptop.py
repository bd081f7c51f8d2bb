"""A decode the size of a Lytro Illum's, in a 16 GB laptop's memory: read 15 x 15 x 434 x 625, keep 9 x 9, deblur.

Usage::

    python benchmarks/bench_laptop.py [--device auto|cpu|cuda] [--out PATH] [--smoke]

The Light Field Toolbox (Dansereau et al.) decodes a Lytro Illum capture to a 15 x 15 x 434 x 625 x 4
array (RGB and a weight channel), 16-bit, in a MATLAB ``.mat`` file; its outer views are dark, and the
central 9 x 9 are the ones people keep. This script renders a scene of that size
(``procedural_scene``, seed 7, ``d_inf = 0``), blurs it by a known path over all 15 x 15 views (as the
camera would), adds noise of sigma 0.005, and writes it as a MATLAB v7.3 file and as a v5 file. Then,
each in a fresh process:

- ``read_lightfield(path, angular_crop=9)`` of each file: seconds and the process's peak memory;
- that read of the v7.3 file followed by ``blind_deblur`` (default parameters, ``require_evidence=False``
  so that the final stage always runs): seconds by stage, the process's peak memory, the evidence verdict,
  and the PSNR gain against the sharp central views.

Peak memory is the whole process's high-water mark (``VmHWM``: the interpreter, torch and the data), the
figure that decides whether a laptop swaps, beside ``estimate_blind_memory`` plus the light field itself.
``--smoke`` runs the same steps on a 7 x 7 x 48 x 64 decode cropped to 5 x 5, and writes no table. The
table goes to ``docs/benchmarks/bench_laptop.md`` (or ``--out``).
"""

from __future__ import annotations

import argparse
import json
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import _report  # noqa: E402  (benchmarks/_report.py)

SHAPE, KEEP = (15, 15, 434, 625), 9
SMOKE_SHAPE, SMOKE_KEEP = (7, 7, 48, 64), 5
PATH = np.array([[-0.9, 0.4, 0.3], [0.3, -0.7, -0.2], [0.8, 0.6, 0.1]])  # bench_fullres.py's path
NOISE = 0.005
GB = 1e9


def peak_rss() -> int:
    """This process's peak resident memory so far, bytes (``VmHWM``)."""
    try:
        for line in Path("/proc/self/status").read_text().splitlines():
            if line.startswith("VmHWM:"):
                return int(line.split()[1]) * 1024
    except OSError:
        pass
    scale = 1 if sys.platform == "darwin" else 1024  # ru_maxrss: bytes on macOS, KiB on Linux
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * scale


def write_decodes(folder: Path, shape) -> dict:
    """Render, blur and write the decode as MATLAB v7.3 and v5; returns the file paths and the sharp views."""
    import h5py
    import scipy.io

    from napari_lfdeblur import simulate_blur
    from napari_lfdeblur.samples import procedural_scene

    sharp = procedural_scene(shape, seed=7, color=True)[0]
    blurred = simulate_blur(sharp, PATH, n_times=64)
    blurred += np.random.default_rng(0).normal(0, NOISE, blurred.shape).astype(np.float32)
    weight = np.ones(blurred.shape[:4] + (1,), np.float32)
    lf16 = np.rint(np.clip(np.concatenate([blurred, weight], axis=-1), 0, 1) * 65535).astype(np.uint16)
    del blurred, weight
    v73, v5 = folder / "decode_v73.mat", folder / "decode_v5.mat"
    with h5py.File(v73, "w", userblock_size=512) as f:
        f.create_dataset("LF", data=lf16.T)  # MATLAB v7.3 stores the axes reversed
    with open(v73, "r+b") as fh:  # MATLAB's text header lives in the user block
        fh.write(b"MATLAB 7.3 MAT-file, HDF5 schema 1.00 .")
    scipy.io.savemat(v5, {"LF": lf16})
    sharp_path = folder / "sharp_central.npy"
    V, U = shape[:2]
    keep = KEEP if shape == SHAPE else SMOKE_KEEP
    np.save(sharp_path, sharp[(V - keep) // 2:(V + keep) // 2, (U - keep) // 2:(U + keep) // 2])
    return {"v73": str(v73), "v5": str(v5), "sharp": str(sharp_path), "file_bytes": int(lf16.nbytes)}


def child(task: dict) -> dict:
    """One measurement, in this (fresh) process."""
    import torch

    from napari_lfdeblur.io import read_lightfield

    torch.set_num_threads(torch.get_num_threads())  # load torch before the baseline
    base = peak_rss()
    t0 = time.perf_counter()
    lf = read_lightfield(task["path"], angular_crop=task["keep"])
    out = {"read_s": time.perf_counter() - t0, "shape": list(lf.shape), "base_gb": base / GB,
           "lf_gb": lf.nbytes / GB}
    if task["blind"]:
        from napari_lfdeblur.blind import blind_deblur, estimate_blind_memory
        from napari_lfdeblur.metrics import psnr

        t0 = time.perf_counter()
        res = blind_deblur(lf, device=task["device"], require_evidence=False)
        out.update(blind_s=time.perf_counter() - t0, peak_gb=peak_rss() / GB)  # before the PSNR's own copies
        sharp = np.load(task["sharp"])
        out.update(path_s=res.timings["path"], final_s=res.timings["final"], blur_found=bool(res.info["blur_found"]),
                   gain=psnr(res.lightfield, sharp) - psnr(lf, sharp),
                   estimate_gb=(estimate_blind_memory(lf.shape) + lf.nbytes) / GB)
    else:
        out["peak_gb"] = peak_rss() / GB
    return out


def measure(task: dict) -> dict:
    proc = subprocess.run([sys.executable, __file__, "--child", json.dumps(task)], capture_output=True, text=True,
                          check=False)
    if proc.returncode != 0:
        print(proc.stderr, file=sys.stderr)
        raise SystemExit(f"{task} failed")
    return json.loads(proc.stdout.strip().splitlines()[-1])


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--device", default="auto")
    parser.add_argument("--smoke", action="store_true", help="a small decode, no table")
    parser.add_argument("--child", help=argparse.SUPPRESS)  # internal: one measurement, printed as JSON
    _report.add_out_argument(parser, __file__)
    args = parser.parse_args(argv)
    if args.child:
        print(json.dumps(child(json.loads(args.child))))
        return 0
    from napari_lfdeblur.devices import select_device

    device = str(select_device(args.device))
    shape, keep = (SMOKE_SHAPE, SMOKE_KEEP) if args.smoke else (SHAPE, KEEP)
    with tempfile.TemporaryDirectory() as tmp:
        files = write_decodes(Path(tmp), shape)
        reads = {v: measure({"path": files[v], "keep": keep, "blind": False}) for v in ("v73", "v5")}
        blind = measure({"path": files["v73"], "keep": keep, "blind": True, "device": device,
                         "sharp": files["sharp"]})
    print(json.dumps({"reads": reads, "blind": blind}), file=sys.stderr)
    size = "x".join(str(s) for s in shape)
    kept = "x".join(str(s) for s in blind["shape"])
    lines = [
        f"The decode: a rendered scene (`procedural_scene`, seed 7) in the Light Field Toolbox's layout, {size} x 4 "
        f"uint16 ({files['file_bytes'] / GB:.2f} GB), blurred by the path "
        f"{PATH.tolist()} (64 instants) over all views, noise sigma {NOISE:g}; read with `angular_crop={keep}` "
        f"to {kept} float32 ({blind['lf_gb']:.2f} GB). Peak memory: the whole process's high-water mark "
        f"(the interpreter and torch alone: {blind['base_gb']:.2f} GB).",
        "",
        "| step | file | time s | peak memory of the process, GB |",
        "|---|---|---|---|",
    ]
    for v, label in (("v73", "MATLAB v7.3 (reads the kept views only)"), ("v5", "MATLAB v5 (read whole)")):
        lines.append(f"| read, `angular_crop={keep}` | {label} | {reads[v]['read_s']:.1f} | {reads[v]['peak_gb']:.2f} |")
    lines.append(f"| read + `blind_deblur` | MATLAB v7.3 | {blind['read_s'] + blind['blind_s']:.1f} "
                 f"(read {blind['read_s']:.1f}, path {blind['path_s']:.1f}, final {blind['final_s']:.1f}) | "
                 f"{blind['peak_gb']:.2f} |")
    lines += ["", f"- `estimate_blind_memory` plus the light field: {blind['estimate_gb']:.2f} GB.",
              f"- Blur found: {'yes' if blind['blur_found'] else 'no'}; PSNR gain of the restored central views "
              f"(restored whatever the evidence): {blind['gain']:+.2f} dB."]
    if not args.smoke:
        lines.append(f"- On a 16 GB laptop the run leaves {16 - blind['peak_gb']:.1f} GB for the system and other "
                     "programs.")
    out = _report.table_path(args.out, __file__, args.smoke)
    if out is None:
        print("\n".join(lines))
    else:
        _report.write_table(out, "A decode the size of a Lytro Illum's: read, crop to 9 x 9 views, deblur",
                            _report.command_line(__file__, argv), _report.machine(device), lines)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
