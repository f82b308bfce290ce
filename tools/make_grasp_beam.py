#!/usr/bin/env python3
"""Writes assets/examples/grasp_beam.grd, the bundled example's GRASP far field (docs/beams.md).

A TICRA .grd file (KTYPE 1, one field set, ICOMP 3: linear co- and cross-polar components, NCOMP 2,
IGRID 1: a uv grid) of an analytic beam, so that the repository holds no third-party beam data:
an elliptical Gaussian power pattern of FWHM 1.5 deg along the co-polar axis (x) and 1.2 deg across it,
the co-polar field its square root times a phase that grows with the angle from the axis (Stokes
patterns ignore it), and a quadrupole cross-polar field
    cx = kappa sin(2 sigma) q e^(1 - q) co,   q = rho^2 / (2 s_x s_y),   kappa = 0.05,
zero on the axis and the principal planes and largest (5% of the co-polar field, -26 dB) on the
diagonals at rho = sqrt(2 s_x s_y): the beam of `[beams.NAME] type = "elliptical"` with fwhm_x_deg = 1.5,
fwhm_y_deg = 1.2, cross_polar = 0.05 and cross_polar_pattern = "quadrupole". The grid spans
|u|, |v| <= sin(5 deg) in 61 x 61 points (10 arcmin apart).

Run with Debian's /usr/bin/python3 (numpy):  /usr/bin/python3 tools/make_grasp_beam.py [OUT.grd]
"""

import math
import sys
from pathlib import Path

import numpy as np

FWHM_X_DEG, FWHM_Y_DEG, KAPPA = 1.5, 1.2, 0.05
HALF_DEG, N = 5.0, 61


def fields(rho, sigma, fwhm_x_deg=FWHM_X_DEG, fwhm_y_deg=FWHM_Y_DEG, kappa=KAPPA):
    to_s = 1.0 / math.sqrt(8.0 * math.log(2.0))
    sx, sy = math.radians(fwhm_x_deg) * to_s, math.radians(fwhm_y_deg) * to_s
    u, v = rho * np.cos(sigma), rho * np.sin(sigma)
    power = np.exp(-(u * u / (2 * sx * sx) + v * v / (2 * sy * sy)))
    q = rho * rho / (2 * sx * sy)
    co = np.sqrt(power) * np.exp(1j * (0.3 + 40.0 * rho))
    return co, kappa * np.sin(2 * sigma) * q * np.exp(1 - q) * co


def write_grd(out, fwhm_x_deg=FWHM_X_DEG, fwhm_y_deg=FWHM_Y_DEG, half_deg=HALF_DEG, n=N, kappa=KAPPA):
    """The beam above with other widths, extent and sampling (tools/accuracy_map.py writes its own)."""
    half = math.sin(math.radians(half_deg))
    axis = np.linspace(-half, half, n)
    u, v = np.meshgrid(axis, axis)  # x (u) runs fastest in the file
    rho = np.arcsin(np.minimum(1.0, np.hypot(u, v)))
    co, cx = fields(rho, np.arctan2(v, u), fwhm_x_deg, fwhm_y_deg, kappa)
    lines = [
        f"PISCO-VK example beam: elliptical Gaussian {fwhm_x_deg:g} x {fwhm_y_deg:g} deg, quadrupole cross-polar "
        f"field (kappa {kappa:g})",
        "written by tools/make_grasp_beam.py; TICRA GRASP grid format",
        "FREQUENCIES [GHz]:",
        "100.0",
        "++++",
        "1",
        "1 3 2 1",
        "0 0",
        f"{-half:.15e} {-half:.15e} {half:.15e} {half:.15e}",
        f"{n} {n} 0",
    ]
    for c, x in zip(co.ravel(), cx.ravel()):
        lines.append(f"{c.real:.9e} {c.imag:.9e} {x.real:.9e} {x.imag:.9e}")
    Path(out).write_text("\n".join(lines) + "\n")


def main():
    out = Path(sys.argv[1]) if len(sys.argv) > 1 else Path(__file__).resolve().parent.parent / "assets/examples/grasp_beam.grd"
    write_grd(out)
    print(f"wrote {out}: {N} x {N} uv grid, |u|, |v| <= sin({HALF_DEG} deg)")


if __name__ == "__main__":
    main()
