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


def fields(rho, sigma):
    to_s = 1.0 / math.sqrt(8.0 * math.log(2.0))
    sx, sy = math.radians(FWHM_X_DEG) * to_s, math.radians(FWHM_Y_DEG) * to_s
    u, v = rho * np.cos(sigma), rho * np.sin(sigma)
    power = np.exp(-(u * u / (2 * sx * sx) + v * v / (2 * sy * sy)))
    q = rho * rho / (2 * sx * sy)
    co = np.sqrt(power) * np.exp(1j * (0.3 + 40.0 * rho))
    return co, KAPPA * np.sin(2 * sigma) * q * np.exp(1 - q) * co


def main():
    out = Path(sys.argv[1]) if len(sys.argv) > 1 else Path(__file__).resolve().parent.parent / "assets/examples/grasp_beam.grd"
    half = math.sin(math.radians(HALF_DEG))
    axis = np.linspace(-half, half, N)
    u, v = np.meshgrid(axis, axis)  # x (u) runs fastest in the file
    rho = np.arcsin(np.minimum(1.0, np.hypot(u, v)))
    co, cx = fields(rho, np.arctan2(v, u))
    lines = [
        "PISCO-VK example beam: elliptical Gaussian 1.5 x 1.2 deg, quadrupole cross-polar field (kappa 0.05)",
        "written by tools/make_grasp_beam.py; TICRA GRASP grid format",
        "FREQUENCIES [GHz]:",
        "100.0",
        "++++",
        "1",
        "1 3 2 1",
        "0 0",
        f"{-half:.15e} {-half:.15e} {half:.15e} {half:.15e}",
        f"{N} {N} 0",
    ]
    for c, x in zip(co.ravel(), cx.ravel()):
        lines.append(f"{c.real:.9e} {c.imag:.9e} {x.real:.9e} {x.imag:.9e}")
    out.write_text("\n".join(lines) + "\n")
    print(f"wrote {out}: {N} x {N} uv grid, |u|, |v| <= sin({HALF_DEG} deg)")


if __name__ == "__main__":
    main()
