"""The blur model with a non-zero infinity disparity against a ray tracer, and a sheared alternative.

Usage::

    python benchmarks/infinity_model_check.py [--n-times 32] [--out PATH]

A scene of textured fronto-parallel planes (``tests/_raytrace.py``) is seen by
a light-field camera refocused so that points at infinity have disparity
``d_inf`` (view ``(v, u)``, pixel ``(y, x)`` sees the ray that the camera
focused at infinity sees at ``(y - d_inf v_c, x - d_inf u_c)``). It is
rendered along an in-plane path; the mean of the renders is the true blurred
light field. Two models predict it from the sharp (identity-pose) render:

- *package*: ``simulate_blur(sharp, path, infinity_disparity=d_inf)``, the
  model of docs/model.md: at each instant the sample at ``(v + s_v, u + s_u,
  y + d_inf s_v, x + d_inf s_u)``, bilinear along every axis;
- *sheared*: the camera focused at infinity (rendered), blurred with
  ``d_inf = 0``, then shifted back to the refocused views (``d_inf`` is an
  integer here, so the shift needs no interpolation).

Both interpolate between views. The package's model does it at a fixed
pixel, which is exact for points at disparity 0 (the focal plane); the
sheared model does it along the disparity of infinity, exact for points at
infinity, which a translation does not blur at all. The error is
``||model - truth|| / ||truth - sharp||`` over the interior; the last
column is the model's change of a scene whose planes are all nearly at
infinity (disparity ``d_inf - 0.02``), against the truth's, as root mean
squares. The table goes to ``docs/benchmarks/infinity_model_check.md`` (or
``--out``).
"""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
sys.path.insert(0, str(HERE.parent / "tests"))
import _raytrace  # noqa: E402  (tests/_raytrace.py)
import _report  # noqa: E402  (benchmarks/_report.py)

SHAPE = (9, 9, 64, 64)
#: disparities of the planes for the camera focused at infinity (background, then squares), px/view
SCENES = ((-0.3, -0.8), (-0.6, -1.4))
PATHS = {"short line": np.array([[-0.8, -0.3, 0.0], [0.8, 0.3, 0.0]]),
         "curve": np.array([[-1.5, 0.5, 0.0], [0.3, -1.0, 0.0], [1.2, 0.6, 0.0]])}
D_INF = (0, 1, 2)


def render(scene, d_inf: int, pose=None) -> np.ndarray:
    """The light field of the camera refocused to ``d_inf`` at ``pose`` (translation only)."""
    V, U, Y, X = SHAPE
    radius = max(X, Y) / 2.0
    u_c = np.arange(U) - (U - 1) / 2.0
    v_c = np.arange(V) - (V - 1) / 2.0
    dx = (np.arange(X)[None, None, None, :] - (X - 1) / 2.0 - d_inf * u_c[None, :, None, None]) / radius
    dy = (np.arange(Y)[None, None, :, None] - (Y - 1) / 2.0 - d_inf * v_c[:, None, None, None]) / radius
    dx, dy = np.broadcast_arrays(dx, dy)
    origins = np.stack(np.broadcast_arrays(u_c[None, :], v_c[:, None], 0.0), axis=-1)[:, :, None, None, :]
    shift = np.zeros(3) if pose is None else np.asarray(pose[:3])
    return _raytrace.trace(scene, origins + shift, np.stack([dx, dy, np.ones_like(dx)], axis=-1))


def refocus(lf: np.ndarray, d_inf: int) -> np.ndarray:
    """View ``(v, u)`` of ``lf`` read at ``(y - d_inf v_c, x - d_inf u_c)``, clamped (integer ``d_inf``)."""
    V, U, Y, X = lf.shape
    out = np.empty_like(lf)
    for v in range(V):
        ys = np.clip(np.arange(Y) - d_inf * (v - (V - 1) // 2), 0, Y - 1)
        for u in range(U):
            xs = np.clip(np.arange(X) - d_inf * (u - (U - 1) // 2), 0, X - 1)
            out[v, u] = lf[v, u][np.ix_(ys, xs)]
    return out


def blurs(scene, d_inf: int, cp, n_times: int) -> tuple[np.ndarray, ...]:
    """``(sharp, truth, package, sheared)``: the refocused camera's sharp light field, its ray-traced blur
    along ``cp`` and the two models' predictions of that blur."""
    from napari_lfdeblur import simulate_blur

    poses = _raytrace.path_poses(cp, n_times)
    truth = sum(render(scene, d_inf, pose) for pose in poses) / n_times
    sharp = render(scene, d_inf).astype(np.float32)
    package = simulate_blur(sharp, cp, n_times=n_times, infinity_disparity=float(d_inf))
    at_infinity = render(scene, 0).astype(np.float32)
    sheared = refocus(simulate_blur(at_infinity, cp, n_times=n_times, infinity_disparity=0.0), d_inf)
    return sharp, truth, package, sheared


def measure(scene, d_inf: int, cp, n_times: int) -> tuple[float, float]:
    """``(package error, sheared error)`` against the ray-traced blur, over the interior."""
    sharp, truth, package, sheared = blurs(scene, d_inf, cp, n_times)
    margins = (math.ceil(np.abs(_raytrace.path_poses(cp, n_times)[:, :2]).max()), 4 * d_inf + 2)
    return (_raytrace.interior_error(package, truth, sharp, *margins),
            _raytrace.interior_error(sheared, truth, sharp, *margins))


def far_scene_change(d_inf: int, cp, n_times: int) -> tuple[float, float, float]:
    """RMS change by the blur of a scene all at disparity ``d_inf - 0.02``: truth, package, sheared."""
    radius = max(SHAPE[2:]) / 2.0
    scene = _raytrace.make_scene(radius, disparities=(-0.02, -0.02), seed=2)
    sharp, *blurred = blurs(scene, d_inf, cp, n_times)
    m = 4 * d_inf + 2
    inner = (slice(2, -2), slice(2, -2), slice(m, -m), slice(m, -m))
    return tuple(float(np.sqrt(np.mean((a[inner] - sharp[inner]) ** 2))) for a in blurred)


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--n-times", type=int, default=32)
    _report.add_out_argument(parser, __file__)
    args = parser.parse_args(argv)
    radius = max(SHAPE[2:]) / 2.0
    lines = ["| planes' disparity (focused at infinity) | d_inf | path | error, package model | "
             "error, sheared model | RMS change of a scene near infinity: truth / package / sheared |",
             "|---|---|---|---|---|---|"]
    print("\n".join(lines), flush=True)
    # the far scene is the same for every scene of the table: one measurement per d_inf and path
    far_change = {(d_inf, name): far_scene_change(d_inf, cp, args.n_times) for d_inf in D_INF
                  for name, cp in PATHS.items()}
    for disparities in SCENES:
        scene = _raytrace.make_scene(radius, disparities=disparities, seed=1)
        for d_inf in D_INF:
            for name, cp in PATHS.items():
                e_pkg, e_sh = measure(scene, d_inf, cp, args.n_times)
                far = far_change[d_inf, name]
                seen = ", ".join(f"{d + d_inf:+g}" for d in disparities)
                lines.append(f"| {', '.join(map(str, disparities))} (seen at {seen}) | {d_inf} | {name} | "
                             f"{e_pkg:.3f} | {e_sh:.3f} | {far[0]:.4f} / {far[1]:.4f} / {far[2]:.4f} |")
                print(lines[-1], flush=True)
    body = [f"Interior relative error `||model - truth|| / ||truth - sharp||` of two blur models against a "
            f"ray-traced truth (`tests/_raytrace.py`), {SHAPE[0]}x{SHAPE[1]}x{SHAPE[2]}x{SHAPE[3]} light fields, "
            f"T = {args.n_times} instants. *Package*: `simulate_blur` with `infinity_disparity=d_inf`, the model of "
            "docs/model.md. *Sheared*: the camera focused at infinity, blurred with `d_inf = 0`, its views then "
            "shifted by `d_inf` px per view (exact at integer `d_inf`). The last column: the root-mean-square "
            "change that the blur makes to a scene all nearly at infinity.",
            "", *lines]
    out = _report.table_path(args.out, __file__)
    _report.write_table(out, "The blur model at a non-zero infinity disparity against a ray tracer",
                        _report.command_line(__file__, argv), _report.machine("auto"), body)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
