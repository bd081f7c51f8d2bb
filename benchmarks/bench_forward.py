"""Speed and memory of the blur operator, against a straightforward grid_sample version.

Usage::

    python benchmarks/bench_forward.py [--shape 9 9 376 541 3] [--n-times 16] [--device auto|cpu|cuda]
        [--variants ours ours-torch grid_sample] [--out PATH]

For each implementation it prints the forward time, the forward+backward
time (loss ``0.5 ||f - b||^2``, gradients for the light field and the control
points) and the peak memory above the baseline during forward+backward, in
units of the light field's size. The baseline is the memory in use once the
light field, the target and the path exist. Each implementation runs in its
own subprocess, so peaks don't mix. The table goes to
``docs/benchmarks/bench_forward.md`` (or ``--out``).
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import threading
import time
from pathlib import Path

import torch
import torch.nn.functional as F

from napari_lfdeblur.blur import BlurOperator, normalized_coordinates
from napari_lfdeblur.devices import select_device
from napari_lfdeblur.path import bezier_positions, random_path

sys.path.insert(0, str(Path(__file__).resolve().parent))
import _report  # noqa: E402  (benchmarks/_report.py)


def gridsample_blur(L, control_points, n_times):
    """The forward model of docs/model.md (d_inf = 0) written directly with grid_sample.

    ``L`` is (V, U, Y, X, C). Every pixel is a batch item whose (V, U) image
    is sampled at the shifted angular coordinates, once per instant.
    """
    V, U, Y, X, C = L.shape
    pos = bezier_positions(control_points, n_times)
    r = max(X, Y) / 2
    xt = normalized_coordinates(X, r, L.dtype, L.device)
    yt = normalized_coordinates(Y, r, L.dtype, L.device)
    img = L.permute(2, 3, 4, 0, 1).reshape(Y * X, C, V, U)
    vv = torch.arange(V, dtype=L.dtype, device=L.device)
    uu = torch.arange(U, dtype=L.dtype, device=L.device)
    out = 0
    for k in range(n_times):
        su = pos[k, 0] - xt * pos[k, 2]  # (X,)
        sv = pos[k, 1] - yt * pos[k, 2]  # (Y,)
        cu = uu[None, None, None, :] + su[None, :, None, None]  # (1, X, 1, U)
        cv = vv[None, None, :, None] + sv[:, None, None, None]  # (Y, 1, V, 1)
        gx = (cu / max(U - 1, 1)) * 2 - 1
        gy = (cv / max(V - 1, 1)) * 2 - 1
        gx, gy = torch.broadcast_tensors(gx, gy)  # (Y, X, V, U)
        grid = torch.stack([gx, gy], dim=-1).reshape(Y * X, V, U, 2)
        out = out + F.grid_sample(img, grid, mode="bilinear", padding_mode="border", align_corners=True)
    out = out / n_times
    return out.reshape(Y, X, C, V, U).permute(3, 4, 0, 1, 2)


class PeakRSS:
    """Peak resident memory of this process, sampled every millisecond in a thread."""

    def __init__(self):
        import psutil

        self.proc = psutil.Process(os.getpid())
        self.peak = 0
        self._stop = threading.Event()

    def __enter__(self):
        self.base = self.proc.memory_info().rss
        self.peak = self.base
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()
        return self

    def _run(self):
        while not self._stop.is_set():
            self.peak = max(self.peak, self.proc.memory_info().rss)
            time.sleep(0.001)

    def __exit__(self, *exc):
        self._stop.set()
        self._thread.join()
        self.peak = max(self.peak, self.proc.memory_info().rss)


def _sync(device):
    if device.type == "cuda":
        torch.cuda.synchronize()


def run_variant(variant, shape, n_times, device, repeats, block_elements=None):
    device = select_device(device)
    torch.manual_seed(0)
    L = torch.rand(shape, device=device)
    cp0 = random_path(4, extent=3.0, z_extent=1.0, seed=1)
    target = torch.rand(shape, device=device)
    lf_bytes = L.numel() * L.element_size()

    def forward(L, cp):
        if variant.startswith("ours"):
            return BlurOperator(shape, cp, n_times=n_times, device=device, block_elements=block_elements).forward(L)
        return gridsample_blur(L, cp, n_times)

    def fwd_bwd():
        Lg = L.detach().requires_grad_(True)
        cp = torch.tensor(cp0, dtype=torch.float32, device=device, requires_grad=True)
        loss = 0.5 * F.mse_loss(forward(Lg, cp), target, reduction="sum")
        loss.backward()
        return Lg.grad, cp.grad

    with torch.no_grad():
        forward(L, torch.tensor(cp0, dtype=torch.float32, device=device))  # warm-up
    t_fwd = []
    for _ in range(repeats):
        _sync(device)
        t0 = time.perf_counter()
        with torch.no_grad():
            out = forward(L, torch.tensor(cp0, dtype=torch.float32, device=device))
        _sync(device)
        t_fwd.append(time.perf_counter() - t0)
        del out
    t_fb = []
    peak_extra = 0.0
    for _ in range(repeats):
        if device.type == "cuda":
            torch.cuda.reset_peak_memory_stats()
            base = torch.cuda.memory_allocated()
        _sync(device)
        with PeakRSS() as mem:
            t0 = time.perf_counter()
            grads = fwd_bwd()
            _sync(device)
            t_fb.append(time.perf_counter() - t0)
        if device.type == "cuda":
            extra = torch.cuda.max_memory_allocated() - base
        else:
            extra = mem.peak - mem.base
        peak_extra = max(peak_extra, extra / lf_bytes)
        del grads
    return {
        "variant": variant,
        "device": str(device),
        "forward_s": min(t_fwd),
        "forward_backward_s": min(t_fb),
        "peak_extra_x_lf": peak_extra,
        "lf_mb": lf_bytes / 2**20,
    }


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--shape", type=int, nargs="+", default=[9, 9, 376, 541, 3])
    parser.add_argument("--n-times", type=int, default=16)
    parser.add_argument("--device", default="auto")
    parser.add_argument("--repeats", type=int, default=2)
    parser.add_argument("--block-elements", type=int, default=None, help="block size of ours (default: per device)")
    variants = ["ours", "ours-torch", "grid_sample"]
    parser.add_argument("--variants", nargs="+", default=variants, choices=variants,
                        help="ours: the default (on the CPU the fused loops, with numba); ours-torch: its torch version")
    parser.add_argument("--variant", choices=variants, help=argparse.SUPPRESS)
    _report.add_out_argument(parser, __file__)
    args = parser.parse_args(argv)
    shape = tuple(args.shape)
    if args.variant:  # child process: one measurement, as JSON
        print(json.dumps(run_variant(args.variant, shape, args.n_times, args.device, args.repeats,
                                     args.block_elements)))
        return
    device = select_device(args.device)
    print(f"blur operator, {shape} float32, T = {args.n_times}, device {device}, torch {torch.__version__}, "
          f"{torch.get_num_threads()} threads")
    rows, failed = [], []
    for variant in args.variants:
        cmd = [sys.executable, __file__, "--variant", variant, "--shape", *map(str, shape),
               "--n-times", str(args.n_times), "--device", str(device), "--repeats", str(args.repeats)]
        if args.block_elements:
            cmd += ["--block-elements", str(args.block_elements)]
        env = {**os.environ, "NAPARI_LFDEBLUR_NUMBA": "0"} if variant == "ours-torch" else None
        res = subprocess.run(cmd, capture_output=True, text=True, env=env)
        if res.returncode != 0:
            print(f"{variant} failed:\n{res.stderr[-2000:]}")
            failed.append(variant)
            continue
        rows.append(json.loads(res.stdout.strip().splitlines()[-1]))
    print(f"{'implementation':<14} {'forward (s)':>12} {'fwd+bwd (s)':>12} {'peak extra (x LF)':>18}")
    for r in rows:
        print(f"{r['variant']:<14} {r['forward_s']:>12.3f} {r['forward_backward_s']:>12.3f} {r['peak_extra_x_lf']:>18.2f}")
    for line in _speed_ups(rows):
        print(line)
    print(f"(light field size: {rows[0]['lf_mb']:.0f} MiB)" if rows else "")
    if rows and not failed:
        _write(rows, shape, args, argv, device)
    return _report.exit_status(failed)


def _speed_ups(rows):
    """Sentences: each of our variants over grid_sample, where both ran."""
    by = {r["variant"]: r for r in rows}
    ref = by.get("grid_sample")
    return [f"Speed-up of {name} over grid_sample: forward {ref['forward_s'] / r['forward_s']:.1f}x, "
            f"forward + backward {ref['forward_backward_s'] / r['forward_backward_s']:.1f}x."
            for name, r in by.items() if ref is not None and name != "grid_sample"]


def _write(rows, shape, args, argv, device):
    """The table file: one row per implementation, then the speed-up."""
    body = [
        f"A random {'x'.join(map(str, shape))} float32 light field ({rows[0]['lf_mb']:.0f} MiB), "
        f"T = {args.n_times}, loss `0.5 ||f - b||^2`, gradients for the light field and the control points; "
        f"best of {args.repeats} runs. Peak memory: the memory in use above the light field, target and path "
        "during forward+backward, in units of the light field's size (resident set size on the CPU, "
        "`torch.cuda.max_memory_allocated` on a GPU). `grid_sample`: the same model written directly with "
        "`torch.nn.functional.grid_sample` (every pixel a batch item). `ours`: the default, which on the CPU runs "
        "the fused loops compiled by numba; `ours-torch`: its torch version (`NAPARI_LFDEBLUR_NUMBA=0`, the one "
        "a GPU runs).",
        "",
        "| implementation | forward (s) | forward + backward (s) | peak extra memory (x light field) |",
        "|---|---|---|---|",
        *[f"| {r['variant']} | {r['forward_s']:.3f} | {r['forward_backward_s']:.3f} | {r['peak_extra_x_lf']:.2f} |"
          for r in rows],
    ]
    body += ["", *_speed_ups(rows)] if _speed_ups(rows) else []
    _report.write_table(_report.table_path(args.out, __file__), "Blur operator: speed and memory",
                        _report.command_line(__file__, argv), _report.machine(str(device)), body)


if __name__ == "__main__":
    raise SystemExit(main())
