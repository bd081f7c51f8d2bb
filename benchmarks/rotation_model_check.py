"""First-order models of camera rotation in the light-field motion blur, against a ray tracer.

Usage::

    python benchmarks/rotation_model_check.py [--n-times 12] [--out PATH] [--smoke]

A scene of textured fronto-parallel planes (``tests/_raytrace.py``) is
rendered by a light-field camera along yaw, pitch, roll and mixed 6-DOF
paths; the mean of the renders is the true blurred light field. Each model
variant predicts it from the sharp light field (the render at the identity
pose) by resampling it at, per instant,
``(v + s_v, u + s_u, y + R dy, x + R dx)``:

- ``first order``: ``s_u = p_x - x~ p_z``, ``s_v = p_y - y~ p_z``,
  ``dx = r_y (1 + x~^2) - r_x x~ y~ - r_z y~``,
  ``dy = -r_x (1 + y~^2) + r_y x~ y~ + r_z x~``;
- ``shift only``: the same without the ``x~^2`` and ``x~ y~`` terms,
  ``dx = r_y - r_z y~``, ``dy = -r_x + r_z x~``;
- ``translation only``: ``dx = dy = 0``, rotation ignored;
- ``+ aperture``: first order plus the motion of the aperture point under the
  rotation, ``s_u += -r_z v_c - x~ w``, ``s_v += r_z u_c - y~ w`` with
  ``w = r_x v_c - r_y u_c``.

Each variant is evaluated twice: by a brute-force clamped quadrilinear gather
of the sampled sharp light field (what a blur operator does), and by tracing
the variant's rays exactly through the scene (its geometric error alone,
without the interpolation's). The package's ``simulate_blur`` with
``(n, 6)`` control points is measured when it accepts them. The error is
``||model - truth|| / ||truth - sharp||`` over the interior (see
``path_margins`` in ``tests/_raytrace.py``). The table goes to
``docs/benchmarks/rotation_model_check.md`` (or ``--out``).
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
sys.path.insert(0, str(HERE.parent / "tests"))
import _raytrace  # noqa: E402  (tests/_raytrace.py)
import _report  # noqa: E402  (benchmarks/_report.py)

VARIANTS = ("first order", "shift only", "translation only", "+ aperture")
EXACT_VARIANTS = ("first order", "shift only", "+ aperture")
#: (views, R): the two sizes, light fields of (views, views, 2R, 2R)
SIZES = ((7, 24), (5, 64))
MAGNITUDES = (0.005, 0.03)
#: disparities of the planes, px/view: unbounded background, then two soft-edged squares in front
DISPARITIES = (-0.5, -1.0, -1.5)
#: range of the textures' wavelengths in the image, px
WAVELENGTHS_PX = (6.0, 12.0)


def model_coordinates(variant: str, pose, shape):
    """Where one instant of a model variant reads the sharp light field.

    Parameters
    ----------
    variant : str
        One of ``VARIANTS``.
    pose : array_like of 6 float
        ``(p_x, p_y, p_z, r_x, r_y, r_z)`` at the instant.
    shape : tuple of 4 int
        ``(V, U, Y, X)``.

    Returns
    -------
    tuple of 4 ndarray, each of ``shape``
        Fractional ``(v, u, y, x)`` indices of the samples.
    """
    V, U, Y, X = shape
    radius = max(X, Y) / 2.0
    px, py, pz, rx, ry, rz = (float(c) for c in pose)
    v, u, y, x = np.meshgrid(*(np.arange(n, dtype=np.float64) for n in shape), indexing="ij")
    xt = (x - (X - 1) / 2.0) / radius
    yt = (y - (Y - 1) / 2.0) / radius
    s_u = px - xt * pz
    s_v = py - yt * pz
    if variant == "translation only":
        dx = dy = 0.0
    elif variant == "shift only":
        dx = ry - rz * yt
        dy = -rx + rz * xt
    elif variant in ("first order", "+ aperture"):
        dx = ry * (1.0 + xt**2) - rx * xt * yt - rz * yt
        dy = -rx * (1.0 + yt**2) + ry * xt * yt + rz * xt
    else:
        raise ValueError(f"unknown variant {variant!r}")
    if variant == "+ aperture":
        u_c = u - (U - 1) / 2.0
        v_c = v - (V - 1) / 2.0
        tilt = rx * v_c - ry * u_c  # z of the rotated aperture point
        s_u = s_u - rz * v_c - xt * tilt
        s_v = s_v + rz * u_c - yt * tilt
    return v + s_v, u + s_u, y + radius * dy, x + radius * dx


def bilinear_gather(lf, coords) -> np.ndarray:
    """``lf`` at fractional ``(v, u, y, x)`` indices: quadrilinear, clamped (replicated boundary)."""
    lf = np.asarray(lf, dtype=np.float64)
    lows, fracs, highs = [], [], []
    for c, n in zip(coords, lf.shape):
        c = np.clip(c, 0.0, n - 1.0)
        low = np.minimum(np.floor(c).astype(np.int64), max(n - 2, 0))
        lows.append(low)
        highs.append(np.minimum(low + 1, n - 1))
        fracs.append(c - low)
    out = np.zeros(np.shape(coords[0]))
    for corner in range(16):
        weight = np.ones_like(out)
        index = []
        for axis in range(4):
            upper = (corner >> axis) & 1
            weight = weight * (fracs[axis] if upper else 1.0 - fracs[axis])
            index.append(highs[axis] if upper else lows[axis])
        out += weight * lf[tuple(index)]
    return out


def model_blur(variant: str, scene, sharp, control_points, n_times: int, exact: bool) -> np.ndarray:
    """A variant's blurred light field: mean over the instants of the sharp one, resampled.

    With ``exact`` the samples are traced through ``scene`` (no interpolation);
    otherwise they are gathered from ``sharp`` by :func:`bilinear_gather`.
    """
    shape = sharp.shape
    acc = np.zeros(shape)
    for pose in _raytrace.path_poses(control_points, n_times):
        coords = model_coordinates(variant, pose, shape)
        if exact:
            acc += _raytrace.sample_sharp(scene, shape, *coords)
        else:
            acc += bilinear_gather(sharp, coords)
    return acc / n_times


def package_blur(sharp, control_points, n_times: int):
    """``napari_lfdeblur.simulate_blur`` with ``(n, 6)`` control points, or None if it refuses them."""
    from napari_lfdeblur.blur import simulate_blur

    try:
        return simulate_blur(sharp.astype(np.float32), control_points, n_times=n_times, device="cpu")
    except ValueError:
        return None


def measure_case(motion: str, n_views: int, radius: int, magnitude: float, n_times: int) -> dict:
    """Interior relative errors of every variant for one motion, size and magnitude."""
    shape = (n_views, n_views, 2 * radius, 2 * radius)
    scene = _raytrace.make_scene(radius, disparities=DISPARITIES, wavelengths_px=WAVELENGTHS_PX)
    cp = _raytrace.motion_paths(magnitude)[motion]
    sharp = _raytrace.render(scene, shape)
    truth = _raytrace.render_blur(scene, shape, cp, n_times)
    margins = _raytrace.path_margins(cp, shape, n_times)

    def error(estimate):
        return _raytrace.interior_error(estimate, truth, sharp, *margins)

    row = {"motion": motion, "shape": shape, "magnitude": magnitude, "margins": margins}
    for variant in VARIANTS:
        row[variant] = error(model_blur(variant, scene, sharp, cp, n_times, exact=False))
    for variant in EXACT_VARIANTS:
        row["exact " + variant] = error(model_blur(variant, scene, sharp, cp, n_times, exact=True))
    package = package_blur(sharp, cp, n_times)
    row["package"] = None if package is None else error(package)
    return row


COLUMNS = [*VARIANTS, "package", *("exact " + v for v in EXACT_VARIANTS)]


def table_line(row: dict) -> str:
    """One markdown table row."""
    V, U, Y, X = row["shape"]
    cells = [row["motion"], f"{V}x{U}x{Y}x{X}", f"{row['magnitude']:.3f}",
             f"{row['magnitude'] * max(X, Y) / 2:.2f}", f"{row['margins'][0]} / {row['margins'][1]}"]
    for column in COLUMNS:
        value = row[column]
        cells.append("n/a" if value is None else f"{value:.3f}")
    return "| " + " | ".join(cells) + " |"


def table_header() -> list[str]:
    """The markdown table's header and rule."""
    names = ["motion", "light field", "r (rad)", "R r (px)", "margin (views / px)", *COLUMNS]
    return ["| " + " | ".join(names) + " |", "|" + "---|" * len(names)]


def write_table(lines: list[str], out, n_times: int, argv) -> None:
    """Write the table and the paragraph that says what it measures."""
    scene = (f"an unbounded background at disparity {DISPARITIES[0]} px/view and soft-edged squares at "
             f"{', '.join(map(str, DISPARITIES[1:]))}, textures of {WAVELENGTHS_PX[0]:g}-"
             f"{WAVELENGTHS_PX[1]:g} px wavelengths; T = {n_times} instants of a curved path from the "
             "identity pose")
    body = [
        (f"Interior relative error `||model - truth|| / ||truth - sharp||` of blur models with camera "
         f"rotation, against a ray-traced truth (`tests/_raytrace.py`: {scene}). The first four columns "
         "resample the sampled sharp light field bilinearly, as a blur operator does (*first order*: the "
         "package's rotation model; *shift only*: without its `x~^2`, `x~ y~` terms; *translation only*: "
         "rotation ignored; *+ aperture*: first order plus the rotation of the aperture point), *package* is "
         "`simulate_blur` with `(n, 6)` control points (n/a where it refuses them), and the *exact* columns "
         "trace each model's rays through the scene, which leaves the model's geometric error without the "
         "interpolation's."),
        "",
        *lines,
    ]
    _report.write_table(out, "Rotation models of the blur against a ray tracer",
                        _report.command_line(__file__, argv), _report.machine("cpu"), body)


def main(argv=None):
    """Measure every case, print the table and write it."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--n-times", type=int, default=8, help="exposure instants T (default 8)")
    parser.add_argument("--smoke", action="store_true", help="one small case, no table file")
    _report.add_out_argument(parser, __file__)
    args = parser.parse_args(argv)
    sizes = SIZES[:1] if args.smoke else SIZES
    magnitudes = MAGNITUDES[-1:] if args.smoke else MAGNITUDES
    motions = ("mixed",) if args.smoke else tuple(_raytrace.motion_paths(0.0))
    lines = table_header()
    print("\n".join(lines), flush=True)
    start = time.perf_counter()
    for n_views, radius in sizes:
        for magnitude in magnitudes:
            for motion in motions:
                lines.append(table_line(measure_case(motion, n_views, radius, magnitude, args.n_times)))
                print(lines[-1], flush=True)
    print(f"{time.perf_counter() - start:.0f} s", file=sys.stderr)
    out = _report.table_path(args.out, __file__, smoke=args.smoke)
    if out is not None:
        write_table(lines, out, args.n_times, argv)


if __name__ == "__main__":
    main()
