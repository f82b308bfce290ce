#!/usr/bin/env python3
"""What the corrected quadrature costs (docs/physics.md, "The quadrature"; BENCHMARKS.md).

For each NSIDE: a band-limited random sky (lmax 2 NSIDE), a 6-pixel-per-FWHM Gaussian beam (rho_max 2.5
FWHM), one detector; the engine made with quadrature="plain" and with "corrected", then the same N random
pointings over the sphere through each (the fraction near the poles that a uniform scan has). The
corrected engine makes its polar copy (resampled around each pole, then packed by the backend beside
the sky as a band of rings) from its construction on a thread of its own; `prepare()` waits for it:
the "copy ready" column is the wait after construction. Prints the set-up and convolution times, their
ratios, the samples on the polar copy, and the memory the engine holds once prepared (the process's
resident memory then, less before the engine was made: the backend's sky, band and beams), measured
in one run.

Run with the Python package built in build/ (scripts/run-tests.sh builds it into build/python):
    PYTHONPATH=build/python build/python-venv/bin/python tools/quadrature_cost.py [--backend simd] [--nside 256 512]
"""

import argparse
import gc
import math
import time

import healpy as hp
import numpy as np

import pisco


def resident_mib():
    """The process's resident memory (Linux), MiB."""
    with open("/proc/self/status") as f:
        for line in f:
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 1024.0
    return float("nan")


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--backend", default="simd")
    ap.add_argument("--nside", type=int, nargs="+", default=[256, 512, 1024])
    ap.add_argument("--samples", type=int, default=200_000)
    args = ap.parse_args()
    rng = np.random.default_rng(1)
    fp = pisco.FocalPlane()
    fp.add("d")
    theta = np.arccos(1 - 2 * rng.random(args.samples))
    phi = 2 * math.pi * rng.random(args.samples)
    psi = 2 * math.pi * rng.random(args.samples)
    print(f"backend {args.backend}, {args.samples:,} random pointings, 6 pixels per FWHM, rho_max 2.5 FWHM")
    print("| NSIDE | quadrature | engine made | copy ready | convolution | total | polar samples | engine memory |")
    print("|---|---|---|---|---|---|---|---|")
    for nside in args.nside:
        lmax = 2 * nside
        cl = 1.0 / (1.0 + (np.arange(lmax + 1) / 30.0) ** 2)
        maps = hp.synfast([cl, 0.3 * cl, 0.1 * cl, 0 * cl], nside, lmax=lmax, new=True)
        sky = pisco.Sky.from_maps(np.ascontiguousarray(maps))
        fwhm = 6 * math.sqrt(math.pi / 3) / nside
        beam = pisco.Beamsor.gaussian(fwhm, rho_max=2.5 * fwhm)
        del maps
        times, memory = {}, {}
        for quadrature in ("plain", "corrected"):
            gc.collect()
            before = resident_mib()
            t0 = time.perf_counter()
            with pisco.Engine(sky, beam, fp, backend=args.backend, quadrature=quadrature) as engine:
                t1 = time.perf_counter()
                engine.prepare()
                t2 = time.perf_counter()
                held = resident_mib() - before
                engine.convolve(0, theta, phi, psi)
                t3 = time.perf_counter()
                polar = engine.polar_samples
            times[quadrature] = (t2 - t0, t3 - t2)
            memory[quadrature] = held
            print(f"| {nside} | {quadrature} | {t1 - t0:.2f} s | {t2 - t1:.2f} s | {t3 - t2:.2f} s | {t3 - t0:.2f} s | "
                  f"{polar:,} | {held:.0f} MiB |", flush=True)
        (sp, cp), (sc, cc) = times["plain"], times["corrected"]
        print(f"|  | corrected / plain | {sc / sp:.2f} (set-up) |  | {cc / cp:.2f} | {(sc + cc) / (sp + cp):.2f} |  | "
              f"{memory['corrected'] / memory['plain']:.2f} |")


if __name__ == "__main__":
    main()
