#!/usr/bin/env python3
"""What point sources cost (docs/sources.md; BENCHMARKS.md): Engine.add_sources for one detector with an
elliptical Gaussian beam (1.0 x 0.7 deg, rho_max 2.5 deg), N samples scattered within 2 deg of a moving
source (each within its disc), 1 to 4 sources; the best of two calls, in nanoseconds per sample and source.
The work is the host's, on the calling thread, whatever the backend.

Run with the Python package built in build/:
    PYTHONPATH=build/python build/python-venv/bin/python tools/sources_cost.py [--samples 1000000]
"""

import argparse
import math
import time

import numpy as np

import pisco


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--samples", type=int, default=1_000_000)
    ap.add_argument("--backend", default="cpu")
    args = ap.parse_args()
    n = args.samples
    fp = pisco.FocalPlane()
    fp.add("d")
    beam = pisco.Beamsor.elliptical_gaussian(math.radians(1.0), math.radians(0.7), 0.3, rho_max=math.radians(2.5))
    rng = np.random.default_rng(1)
    theta = 1.2 + rng.uniform(-0.03, 0.03, n)
    phi = 0.5 + rng.uniform(-0.03, 0.03, n)
    psi = rng.uniform(0, 2 * math.pi, n)
    t = np.linspace(0, 600, n)
    with pisco.Engine(pisco.Sky(64), beam, fp, backend=args.backend) as engine:
        for count in (1, 4):
            tracks = [pisco.SourceTrack(f"s{k}", [0.0, 600.0], [1.2 + 0.001 * k, 1.205], [0.5, 0.505], [1.0, 1.0])
                      for k in range(count)]
            best = math.inf
            for _ in range(2):
                t0 = time.perf_counter()
                engine.add_sources(0, t, tracks, theta, phi, psi)
                best = min(best, time.perf_counter() - t0)
            print(f"{count} source(s), {n:,} samples: {best:.3f} s, {best / (n * count) * 1e9:.0f} ns per sample and source")


if __name__ == "__main__":
    main()
