#!/usr/bin/env python3
"""Cost of a beam's sidelobes against the disc's radius, whole and split (docs/beams.md, "Sidelobes").

A 1 deg FWHM Gaussian main beam with a -30 dB ring of 3 deg FWHM at 10 deg (the beam of
docs/validation.md, K3) on a sky of NSIDE 512 (8.7 pixels per FWHM), 5,000 random pointings, one
detector: the main beam alone to rho_max = 5 deg (5 FWHM), then the whole beam to rho_max = 10, 15, 20,
30 deg summed over the whole disc, and split at 5 deg (the outer part on the band-limited sky at the
NSIDE the engine chooses). Prints the set-up (the engine's construction and prepare(): the polar
copies of the sky and, for a split beam, of its coarse sky), the convolution time of each, its pixel
evaluations per second and its ratio to the main beam alone, measured in one run. --quadrature plain
leaves both polar copies out (docs/physics.md, "The quadrature").

Run with the Python package built in build/ (scripts/run-tests.sh builds it into build/python):
    PYTHONPATH=build/python build/python-venv/bin/python tools/sidelobe_cost.py [--backend simd] [--nside 512]
"""

import argparse
import math
import time

import numpy as np

import pisco
from pisco import deg


def ring_beam(rho, sigma):
    s = 1.0 * deg / math.sqrt(8 * math.log(2.0))
    sr = 3.0 * deg / math.sqrt(8 * math.log(2.0))
    main = math.exp(-rho * rho / (2 * s * s))
    ring = 1e-3 * math.exp(-((rho - 10 * deg) ** 2) / (2 * sr * sr))
    k = 0.1 * math.sin(2 * sigma)
    i, q, u = main + ring * (1 + k * k), main + ring * (1 - k * k), ring * 2 * k
    return [[i, 0, 0, 0], [0, q, u, 0], [0, -u, q, 0], [0, 0, 0, math.hypot(q, u)]]


def main():
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--backend", default="simd")
    p.add_argument("--nside", type=int, default=512)
    p.add_argument("--samples", type=int, default=5000)
    p.add_argument("--radii", type=float, nargs="+", default=[10.0, 15.0, 20.0, 30.0], help="rho_max (deg)")
    p.add_argument("--whole", action=argparse.BooleanOptionalAction, default=True,
                   help="also time the whole discs (slow at large rho_max)")
    p.add_argument("--repeat", type=int, default=2, help="convolutions timed per case (the fastest is kept)")
    p.add_argument("--quadrature", default="corrected", choices=["corrected", "plain"])
    a = p.parse_args()
    rng = np.random.default_rng(1)
    npix = 12 * a.nside**2
    sky = pisco.Sky.from_maps(rng.normal(size=(3, npix)))
    theta = np.arccos(rng.uniform(-1, 1, a.samples))
    phi = rng.uniform(0, 2 * np.pi, a.samples)
    psi = rng.uniform(-np.pi, np.pi, a.samples)
    fp = pisco.FocalPlane()
    fp.add("d", zeta=0.0)
    step = 0.05 * deg
    cases = [("main beam alone", 5.0, None)]
    for r in a.radii:
        if a.whole:
            cases.append(("whole disc", r, None))
        cases.append(("split at 5 deg", r, 5.0))
    print(f"backend {a.backend}, sky NSIDE {a.nside}, {a.samples} samples, quadrature {a.quadrature}; "
          "beam: 1 deg Gaussian + -30 dB ring at 10 deg")
    print(f"{'case':<16} {'rho_max':>7} {'outer NSIDE':>11} {'set-up s':>8} {'pixels/sample':>13} {'time s':>8} "
          f"{'eval/s':>9} {'x main':>7}")
    base = None
    for name, rho, split in cases:
        beam = pisco.Beamsor.from_field(ring_beam, rho * deg, step, "ring beam",
                                        sidelobes=None if split is None else split * deg)
        t0 = time.perf_counter()
        engine = pisco.Engine(sky, beam, fp, backend=a.backend, quadrature=a.quadrature)
        engine.prepare()
        setup = time.perf_counter() - t0
        engine.convolve(0, theta[:100], phi[:100], psi[:100])  # warm up
        best = float("inf")
        for _ in range(a.repeat):
            t0 = time.perf_counter()
            engine.convolve(0, theta, phi, psi)
            best = min(best, time.perf_counter() - t0)
        pixels = engine.mean_disc_pixels
        if base is None:
            base = best
        print(f"{name:<16} {rho:7.1f} {engine.sidelobe_nside or '-':>11} {setup:8.2f} {pixels:13.0f} {best:8.3f} "
              f"{pixels * a.samples / best:9.2e} {best / base:7.2f}", flush=True)
        engine.close()
    ducc0_peer(a, theta, phi, psi)


def ducc0_peer(a, theta, phi, psi):
    """The same samples through ducc0's totalconvolve (where installed): a sky of lmax 3 NSIDE - 1 and a
    beam of kmax 4 (the ring's cross-polar term has m = 2), whose cost does not depend on its extent."""
    try:
        import ducc0
    except ImportError:
        print("ducc0 not installed: no peer figure")
        return
    lmax, kmax = 3 * a.nside - 1, 4
    rng = np.random.default_rng(2)
    size = (lmax + 1) * (lmax + 2) // 2
    sky = rng.normal(size=(3, size)) + 1j * rng.normal(size=(3, size))
    sky[:, : lmax + 1] = sky[:, : lmax + 1].real
    blm = np.full((3, (kmax + 1) * (lmax + 1) - kmax * (kmax + 1) // 2), 1e-3, dtype=np.complex128)
    t0 = time.perf_counter()
    interp = ducc0.totalconvolve.Interpolator(sky, blm, False, lmax, kmax, epsilon=1e-5, nthreads=2)
    t1 = time.perf_counter()
    interp.interpol(np.stack([theta, phi, psi], axis=1))
    t2 = time.perf_counter()
    print(f"ducc0 {ducc0.__version__} totalconvolve (lmax {lmax}, kmax {kmax}, epsilon 1e-5, 2 threads): "
          f"set-up {t1 - t0:.2f} s, {len(theta)} samples {t2 - t1:.3f} s")


if __name__ == "__main__":
    main()
