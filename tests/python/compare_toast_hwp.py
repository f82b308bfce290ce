"""Compare PISCO-VK's TOD through an ideal half-wave plate with TOAST's Stokes weights through one.

For each observation: TOAST's export (tools/toast_pointing.py --hwp-rpm: ``hwp_angle``, the
detectors' ``quats`` and ``weights``, their ``gamma_rad`` and ``pol_leakage``) and three PISCO-VK
TOD files made on uniform skies I = 1, Q = 1 and U = 1 with ``normalization = "per_sample"``, so
that each TOD is one column of the weights. Checks, detector by detector and sample by sample:

- the I TOD against TOAST's I weight (exact up to rounding: bar 1e-12);
- the Q and U TOD against TOAST's Q and U weights, to the tolerance (the beam's width makes a
  uniform Q map differ from a constant Q in the detector's basis; see run_toast_hwp.py);
- the Q and U TOD against the weights of six convention errors, computed from TOAST's own alpha
  (from its detector quaternions), hwp_angle, gamma and eta: the plate's angle in the other sense
  (theta = gamma - h), gamma with the other sign (theta = h + gamma), gamma ignored (theta = h), the
  angle not doubled (2 (alpha + theta)), U with the other sign, no plate at all. Each must miss by
  more than 0.1: the comparison can tell the conventions apart.

TOAST's kernel: ang = 2 (2 (gamma - h) - alpha), weights (1, eta cos ang, -eta sin ang) (COSMO);
PISCO-VK's ideal plate: Q cos 2 (chi + 2 theta) + U sin 2 (chi + 2 theta), theta = h - gamma,
chi = alpha: the same numbers.

Usage: compare_toast_hwp.py [--tolerance T] --observation KIND TOAST_H5 TOD_I TOD_Q TOD_U [...]
"""

import argparse
import sys

import h5py
import numpy as np

MISS = 0.1  # a convention error must be at least this far from PISCO-VK's TOD


def toast_alpha(quats):
    """TOAST's polarization angle alpha from its detector quaternions (x, y, z, w)."""
    q = quats / np.linalg.norm(quats, axis=1)[:, None]
    x, y, z, w = q.T
    ox = np.stack([1 - 2 * (y * y + z * z), 2 * (x * y + z * w), 2 * (x * z - y * w)], axis=1)
    dz = np.stack([2 * (x * z + y * w), 2 * (y * z - x * w), 1 - 2 * (x * x + y * y)], axis=1)
    theta = np.arccos(np.clip(dz[:, 2], -1.0, 1.0))
    phi = np.arctan2(dz[:, 1], dz[:, 0])
    th_hat = np.stack([np.cos(theta) * np.cos(phi), np.cos(theta) * np.sin(phi), -np.sin(theta)], axis=1)
    ph_hat = np.stack([-np.sin(phi), np.cos(phi), np.zeros_like(phi)], axis=1)
    return np.arctan2(np.sum(ox * ph_hat, axis=1), np.sum(ox * th_hat, axis=1)), theta


def wrong_conventions(alpha, h, gamma, eta):
    """(name, Q weight, U weight) of each convention error."""
    def qu(angle, u_sign=1.0):
        return eta * np.cos(2 * angle), u_sign * eta * np.sin(2 * angle)

    theta = h - gamma
    return [
        ("plate angle in the other sense (theta = gamma - h)", *qu(alpha - 2 * theta)),
        ("gamma with the other sign (theta = h + gamma)", *qu(alpha + 2 * (h + gamma))),
        ("gamma ignored (theta = h)", *qu(alpha + 2 * h)),
        ("plate angle not doubled (2 (alpha + theta))", *qu(alpha + theta)),
        ("U with the other sign", *qu(alpha + 2 * theta, -1.0)),
        ("no plate", *qu(alpha)),
    ]


def compare(kind, toast_path, tod_paths, tolerance):
    worst = [0.0, 0.0, 0.0]
    where = ["-", "-", "-"]
    misses = {}
    min_theta = np.pi
    with h5py.File(toast_path, "r") as toast:
        if "hwp_angle" not in toast:
            raise SystemExit(f"{kind}: {toast_path} has no hwp_angle (tools/toast_pointing.py --hwp-rpm?)")
        h = np.asarray(toast["hwp_angle"], dtype=np.float64)
        names = [n.decode() if isinstance(n, bytes) else str(n) for n in toast["detectors"].attrs["names"]]
        tods = [h5py.File(p, "r") for p in tod_paths]
        try:
            for name in names:
                t = toast["detectors"][name]
                weights = np.asarray(t["weights"], dtype=np.float64)
                gamma = float(t.attrs["gamma_rad"])
                eps = float(t.attrs["pol_leakage"])
                eta = (1 - eps) / (1 + eps)
                mine = []
                for stokes, tod in zip("IQU", tods):
                    if name not in tod:
                        raise SystemExit(f"{kind}: {tod.filename} lacks detector '{name}'")
                    signal = np.asarray(tod[name]["signal"], dtype=np.float64)
                    if len(signal) != len(weights):
                        raise SystemExit(f"{kind}: '{name}' has {len(signal)} samples in {tod.filename}, "
                                         f"{len(weights)} in TOAST's")
                    mine.append(signal)
                for c in range(3):
                    dev = float(np.max(np.abs(mine[c] - weights[:, c])))
                    if dev > worst[c]:
                        worst[c], where[c] = dev, name
                alpha, theta = toast_alpha(np.asarray(t["quats"], dtype=np.float64))
                min_theta = min(min_theta, float(np.min(np.minimum(theta, np.pi - theta))))
                for label, wq, wu in wrong_conventions(alpha, h, gamma, eta):
                    miss = max(float(np.max(np.abs(mine[1] - wq))), float(np.max(np.abs(mine[2] - wu))))
                    misses[label] = max(misses.get(label, 0.0), miss)
        finally:
            for tod in tods:
                tod.close()
    ok_i = worst[0] <= 1e-12
    ok_qu = worst[1] <= tolerance and worst[2] <= tolerance
    ok_miss = all(m > MISS for m in misses.values())
    print(f"{kind}: {len(names)} detectors x {len(h)} samples, plate angle from TOAST's hwp_angle, lines of "
          f"sight at least {np.degrees(min_theta):.1f} deg from the poles")
    print(f"  PISCO-VK TOD - TOAST weight, worst: I {worst[0]:.1e} ({where[0]}), Q {worst[1]:.1e} ({where[1]}), "
          f"U {worst[2]:.1e} ({where[2]}); bars 1e-12 (I), {tolerance:g} (Q, U): "
          f"{'ok' if ok_i and ok_qu else 'FAILED'}")
    for label, miss in misses.items():
        print(f"  a convention error, {label}: worst |TOD - its weight| {miss:.2f} "
              f"({'told apart' if miss > MISS else 'NOT told apart'})")
    return ok_i and ok_qu and ok_miss


def main():
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--tolerance", type=float, default=1e-3)
    p.add_argument("--observation", nargs=5, action="append", required=True,
                   metavar=("KIND", "TOAST_H5", "TOD_I", "TOD_Q", "TOD_U"))
    args = p.parse_args()
    ok = True
    for kind, toast_path, *tods in args.observation:
        ok = compare(kind, toast_path, tods, args.tolerance) and ok
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
