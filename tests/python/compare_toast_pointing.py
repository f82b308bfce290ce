"""Compare PISCO-VK's detector pointing (tod.h5) with TOAST's (tools/toast_pointing.py's export).

For every detector of TOAST's file and every sample:

- line of sight: TOAST's ``dir`` against the unit vector at PISCO-VK's (theta, phi);
- polarization orientation: TOAST's alpha = atan2(w_U, w_Q) / 2 from its Stokes weights against
  PISCO-VK's psi + zeta, modulo pi;
- Stokes weights: TOAST's (w_I, w_Q, w_U) against PISCO-VK's measurement weights
  gain/2 (1 + eps), gain/2 (1 - eps) (cos 2 chi, sin 2 chi), chi = psi + zeta.

Prints the worst figures per observation and exits 1 when an angle is off by more than the tolerance
(radians; the weights are held to the same number).

Usage: compare_toast_pointing.py [--tolerance T] --pair KIND TOAST_H5 TOD_H5 [--pair ...]
"""

import argparse
import sys

import h5py
import numpy as np


def compare(kind, toast_path, tod_path, tolerance):
    worst_los = worst_angle = worst_weight = 0.0
    where = {}
    with h5py.File(toast_path, "r") as toast, h5py.File(tod_path, "r") as tod:
        names = [n.decode() if isinstance(n, bytes) else str(n) for n in toast["detectors"].attrs["names"]]
        missing = [n for n in names if n not in tod]
        if missing:
            raise SystemExit(f"{kind}: {tod_path} lacks detectors {missing}")
        extra = [n for n in tod if n not in names]
        if extra:
            raise SystemExit(f"{kind}: {tod_path} has detectors TOAST does not: {extra}")
        samples = 0
        for name in names:
            t = toast["detectors"][name]
            g = tod[name]
            for key in ("theta", "phi", "psi"):
                if key not in g:
                    raise SystemExit(f"{kind}: {tod_path} group '{name}' has no '{key}' (tod_pointing = true?)")
            theta, phi, psi = (np.asarray(g[k], dtype=np.float64) for k in ("theta", "phi", "psi"))
            zeta, eps, gain = (float(g.attrs[k]) for k in ("zeta", "epsilon", "gain"))
            vdir = np.asarray(t["dir"], dtype=np.float64)
            weights = np.asarray(t["weights"], dtype=np.float64)
            if len(theta) != len(vdir):
                raise SystemExit(f"{kind}: '{name}' has {len(theta)} samples in {tod_path}, {len(vdir)} in TOAST's")
            samples = len(theta)
            mine = np.stack([np.sin(theta) * np.cos(phi), np.sin(theta) * np.sin(phi), np.cos(theta)], axis=1)
            los = float(np.max(np.linalg.norm(mine - vdir, axis=1)))
            alpha = 0.5 * np.arctan2(weights[:, 2], weights[:, 1])
            chi = psi + zeta
            d = np.remainder(chi - alpha + np.pi / 2, np.pi) - np.pi / 2
            angle = float(np.max(np.abs(d)))
            mine_w = np.stack([np.full_like(chi, gain / 2 * (1 + eps)),
                               gain / 2 * (1 - eps) * np.cos(2 * chi),
                               gain / 2 * (1 - eps) * np.sin(2 * chi)], axis=1)
            weight = float(np.max(np.abs(mine_w - weights)))
            if los > worst_los:
                worst_los, where["los"] = los, name
            if angle > worst_angle:
                worst_angle, where["angle"] = angle, name
            if weight > worst_weight:
                worst_weight, where["weight"] = weight, name
    ok = worst_los <= tolerance and worst_angle <= tolerance and worst_weight <= tolerance
    print(f"{kind}: {len(names)} detectors x {samples} samples: worst line of sight {worst_los:.2e} rad "
          f"({where.get('los', '-')}), orientation {worst_angle:.2e} rad ({where.get('angle', '-')}), "
          f"Stokes weights {worst_weight:.2e} ({where.get('weight', '-')}); tolerance {tolerance:g}: "
          f"{'ok' if ok else 'FAILED'}")
    return ok


def main():
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--tolerance", type=float, default=1e-10)
    p.add_argument("--pair", nargs=3, action="append", required=True, metavar=("KIND", "TOAST_H5", "TOD_H5"))
    args = p.parse_args()
    ok = True
    for kind, toast_path, tod_path in args.pair:
        ok = compare(kind, toast_path, tod_path, args.tolerance) and ok
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
