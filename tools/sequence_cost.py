#!/usr/bin/env python3
"""Cost of a beam that changes with time, and of one that turns with the plate, against a fixed beam (docs/changing.md).

One engine holds a fixed elliptical beam and a detector whose beam drifts between two elliptical
beams (Detector.beam_sequence: the first at the first and last samples' times, the second halfway). The same samples (random
pointings over the sphere, 5 deg discs by default) are convolved, scattered back (adjoint) and, for
the sequence, also with its samples' times shuffled, so that neighbouring samples fall between
different nodes (runs of one sample: the worst case of the submission's bookkeeping). Prints the
best of --repeat times of each and the ratios to the fixed beam, measured in one run. Then a beam that
turns with a half-wave plate (pisco.PlateBeams, five beams over the plate's period: harmonics up to
4 theta) against the fixed beam behind the engine's own plate model (Detector.hwp), at plate angles
turning through the samples.

Run with the Python package built in build/ (scripts/run-tests.sh builds it into build/python):
    PYTHONPATH=build/python build/python-venv/bin/python tools/sequence_cost.py [--backend simd]
"""

import argparse
import time

import numpy as np

import pisco
from pisco import deg


def best(f, repeat):
    t = float("inf")
    for _ in range(repeat):
        t0 = time.perf_counter()
        f()
        t = min(t, time.perf_counter() - t0)
    return t


def main():
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--backend", default="simd")
    p.add_argument("--nside", type=int, default=256)
    p.add_argument("--samples", type=int, default=20000)
    p.add_argument("--rho-max", type=float, default=5.0, help="disc radius (deg)")
    p.add_argument("--repeat", type=int, default=3)
    a = p.parse_args()
    rng = np.random.default_rng(1)
    sky = pisco.Sky.from_maps(rng.normal(size=(3, 12 * a.nside**2)))
    n = a.samples
    theta = np.arccos(rng.uniform(-1, 1, n))
    phi = rng.uniform(0, 2 * np.pi, n)
    psi = rng.uniform(-np.pi, np.pi, n)
    t = np.linspace(0.0, 3600.0, n)
    shuffled = rng.permutation(t)
    options = dict(rho_max=a.rho_max * deg)
    beams = [pisco.Beamsor.elliptical_gaussian(1.5 * deg, 1.2 * deg, angle=0.2, **options),
             pisco.Beamsor.elliptical_gaussian(1.7 * deg, 1.3 * deg, angle=0.5, **options)]
    fp = pisco.FocalPlane()
    fp.add("fixed", beam=0)
    fp.add("drift", beam_sequence=[(0.0, 0), (1800.0, 1), (3600.0, 0)])
    fp.add("plated", beam=0, hwp=pisco.HalfWavePlate())
    fp.add("turning", plate_beams=pisco.PlateBeams([0, 1, 0, 1, 0]))
    h = np.linspace(0.0, 200.0, n)
    tod = np.zeros(n)
    with pisco.Engine(sky, beams, fp, backend=a.backend) as engine:
        engine.prepare()
        engine.convolve("fixed", theta[:100], phi[:100], psi[:100], out=tod[:100])  # warm up
        cases = [
            ("convolve, fixed beam", lambda: engine.convolve("fixed", theta, phi, psi, out=tod)),
            ("convolve, sequence", lambda: engine.convolve("drift", theta, phi, psi, out=tod, time=t)),
            ("convolve, sequence, shuffled times",
             lambda: engine.convolve("drift", theta, phi, psi, out=tod, time=shuffled)),
        ]
        info = {b.name: b for b in pisco.devices()}
        cases += [
            ("plate, fixed beam and plate model", lambda: engine.convolve("plated", theta, phi, psi, out=tod, hwp_angle=h)),
            ("plate, five plate beams", lambda: engine.convolve("turning", theta, phi, psi, out=tod, hwp_angle=h)),
        ]
        if info[engine.backend].capabilities["adjoint"]:
            cases += [
                ("adjoint, fixed beam", lambda: engine.adjoint("fixed", tod, theta, phi, psi)),
                ("adjoint, sequence", lambda: engine.adjoint("drift", tod, theta, phi, psi, time=t)),
            ]
        print(f"backend {engine.backend}, sky NSIDE {a.nside}, {n} samples, rho_max {a.rho_max} deg, "
              f"best of {a.repeat}")
        base = {}
        for name, f in cases:
            s = best(f, a.repeat)
            kind = name.split(",")[0]
            base.setdefault(kind, s)
            print(f"{name:<36} {s:8.3f} s  {s / base[kind]:5.2f} x the fixed beam", flush=True)


if __name__ == "__main__":
    main()
