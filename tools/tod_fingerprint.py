#!/usr/bin/env python3
"""TOD and adjoint fingerprints: every kernel path of every backend present, bit for bit, before and
after a change.

A change that should move no number (a refactoring, a file moved) is checked by running
  tod_fingerprint.py record before.npz      (on the old build)
  tod_fingerprint.py record after.npz       (on the new build)
  tod_fingerprint.py compare before.npz after.npz
with the package importable (PYTHONPATH=build/python build/python-venv/bin/python ...). The cases:
skies without and with a 2.725 K monopole, a round (radial) and an elliptical (grid) beam, without and
with a generic plate at the aperture, integral and per-sample normalization, two detectors (one off
the boresight), pointing as angles and as quaternions, 400 samples of which 200 lie within 0.15 rad
of the poles; on cpu, simd, vulkan (and vulkan in float-float). Each TOD is also scattered back
(engine.adjoint, on the backends that have it), each detector's adjoint_diagonal taken, and its normal
pass (engine.normal, A^T A of the sky): the maps are fingerprinted too. compare exits 1 when any array differs.

  tod_fingerprint.py record OUT.npz [--threads N] [--chunk-samples N]
records with N threads on the host backends (cpu, simd; 2 by default) and chunks of N samples on the
device backends (0, the default: what fits the device). The engine promises the same bits whatever
either is (docs/simd.md, docs/vulkan.md): tests/python/test_fingerprints.py records with other values
and compares.
"""
import argparse
import sys

import numpy as np


def record(path, threads=2, chunk_samples=0):
    import pisco

    rng = np.random.default_rng(7)
    nside = 32
    npix = 12 * nside * nside
    base = [rng.normal(0, 1e-4, npix) for _ in range(4)]
    n = 400
    theta = np.concatenate([rng.uniform(0, 0.15, n // 4), rng.uniform(np.pi - 0.15, np.pi, n // 4),
                            np.arccos(rng.uniform(-1, 1, n // 2))])
    phi = rng.uniform(0, 2 * np.pi, n)
    psi = rng.uniform(0, 2 * np.pi, n)
    quats = np.array([pisco.quat_from_pointing(t, p, s) for t, p, s in zip(theta, phi, psi)])
    angle = rng.uniform(0, 2 * np.pi, n)
    m0 = np.eye(4) * np.array([1, 1, -1, -1]) * 0.98 + rng.normal(0, 0.005, (4, 4))
    out = {}
    devices = [b for b in pisco.devices() if b.available and b.name != "cuda"]
    backends = [b.name for b in devices]
    adjoint = {b.name: b.capabilities["adjoint"] for b in devices}
    for mono in (0.0, 2.725):
        sky = pisco.Sky.from_maps([base[0] + mono, base[1], base[2], base[3]])
        # rho_max 12 deg: the polar copy's reach (35 deg) within 32 rings of each pole, whose fit is the
        # cheaper (docs/physics.md, "The quadrature"); every path is still taken.
        beams = [pisco.Beamsor.gaussian(np.radians(8.0), np.radians(12.0)),
                 pisco.Beamsor.elliptical_gaussian(np.radians(9.0), np.radians(6.0), 0.3, np.radians(12.0))]
        for bi, beam in enumerate(beams):
            for plate in (None, "aperture"):
                fp = pisco.FocalPlane()
                hwp = pisco.HalfWavePlate(m0) if plate else None
                fp.add("a", zeta=0.3, epsilon=0.01, gain=1.1, beam=0, hwp=hwp)
                fp.add("b", zeta=1.2, beam=0, offset=pisco.offset_quat(0.02, -0.01, 0.4), hwp=hwp)
                for norm in ("integral", "per_sample"):
                    for be in backends:
                        for ar in (["auto", "float-float"] if be == "vulkan" else ["auto"]):
                            # the host backends' threads, the device backends' chunks
                            host = dict(threads=threads) if be in ("cpu", "simd") else dict(chunk_samples=chunk_samples)
                            e = pisco.Engine(sky, [beam], fp, backend=be, normalization=norm, arithmetic=ar, **host)
                            for d in ("a", "b"):
                                kw = dict(hwp_angle=angle) if plate else {}
                                key = f"m{mono}_b{bi}_{plate}_{norm}_{be}_{ar}_{d}"
                                out[key + "_ang"] = e.convolve(d, theta, phi, psi, **kw)
                                out[key + "_quat"] = e.convolve(d, boresight_quats=quats, **kw)
                                if adjoint[be]:
                                    out[key + "_adj_ang"] = e.adjoint(d, out[key + "_ang"], theta, phi, psi, **kw)
                                    out[key + "_adj_quat"] = e.adjoint(d, out[key + "_quat"], boresight_quats=quats,
                                                                       **kw)
                                    out[key + "_diag"] = e.adjoint_diagonal(d, theta, phi, psi, **kw)
                                    out[key + "_normal"] = e.normal(d, theta, phi, psi, **kw)
                            e.close()
    np.savez(path, **out)
    print(f"{path}: {len(out)} arrays ({', '.join(backends)})")


def compare(a_path, b_path):
    a, b = np.load(a_path), np.load(b_path)
    differ = 0
    for k in sorted(set(a.files) | set(b.files)):
        if k not in a.files or k not in b.files:
            print(f"only in one file: {k}")
            differ += 1
            continue
        x, y = a[k], b[k]
        if x.shape != y.shape or not np.array_equal(x.view(np.uint64), y.view(np.uint64)):
            n = np.count_nonzero(x.view(np.uint64) != y.view(np.uint64)) if x.shape == y.shape else x.size
            print(f"differs: {k}: {n} of {x.size} samples")
            differ += 1
    print(f"{len(a.files) - differ} of {len(a.files)} arrays identical bit for bit")
    return 1 if differ else 0


if __name__ == "__main__":
    if len(sys.argv) >= 3 and sys.argv[1] == "record":
        ap = argparse.ArgumentParser(prog="tod_fingerprint.py record")
        ap.add_argument("out")
        ap.add_argument("--threads", type=int, default=2)
        ap.add_argument("--chunk-samples", type=int, default=0)
        a = ap.parse_args(sys.argv[2:])
        record(a.out, a.threads, a.chunk_samples)
    elif len(sys.argv) == 4 and sys.argv[1] == "compare":
        sys.exit(compare(sys.argv[2], sys.argv[3]))
    else:
        sys.exit(__doc__)
