"""Where MuellerConvolver's effective beam departs from the exact one, m by m (no sky, no TOD).

The ideal plate at angle alpha turns the beam's spin -2 part P- = Q - iU into spin +2:
P+_eff(x) = C21 e^{4i alpha} e^{-4i phi} P-(x) (the Ludwig-3 conjugation written in the polar basis).
litebird_sim 0.18's MuellerConvolver does this on the coefficients, P+_eff[l, m] = C21 e^{4i alpha}
P-[l, m + 4]: the same l, spin -2 -> +2. That equates d^l_{m+4, 2} with d^l_{m, -2} (healpy's
spin-s harmonics go as d^l_{m,-s}), true only for m = -2 (d^l_{2,2} = d^l_{-2,-2}); elsewhere it is the
flat-sky approximation (both ~ J_{m+2}(l theta)). A beam on its axis has its polarization at m = -2
(+ the ellipticity's m = -2 +- 2k, small); a beam off its axis spreads it over all m.

Printed, for the plate at alpha = 0 and each offset: per m, ||P+_eff(MC) - P+_eff(exact)|| / ||P+_eff(exact)||
over l <= 512, and the m's share of the effective beam's power.
Usage: python mshift_check.py [--offsets 0 0.3 1 2]"""
import argparse

import numpy as np

from common import IDEAL, beam_blm
from mueller_reference import effective_beams, pplus_by_m

p = argparse.ArgumentParser()
p.add_argument("--offsets", type=float, nargs="+", default=[0.0, 0.3, 1.0, 2.0])
args = p.parse_args()
LS, LB, MM = 512, 768, 12


for off in args.offsets:
    blm = beam_blm(LB, MM, off)
    mc_raw, ex_raw = effective_beams(blm, LB, MM, LS, IDEAL)
    mc, ex = mc_raw[0], ex_raw[0]
    a, b = pplus_by_m(mc[1:3], LS, MM + 4), pplus_by_m(ex[1:3], LS, MM + 4)
    total = sum(np.sum(np.abs(v) ** 2) for v in b.values())
    diff_all = np.sqrt(sum(np.sum(np.abs(a[m] - b[m]) ** 2) for m in b) / total)
    print(f"offset {off} deg: whole effective spin +2 beam: ||MC - exact|| / ||exact|| = {diff_all:.2e}")
    rows = []
    for m in range(-MM - 4, MM + 5):
        pw = np.sum(np.abs(b[m]) ** 2) / total
        if pw < 1e-8:
            continue
        d = np.sqrt(np.sum(np.abs(a[m] - b[m]) ** 2) / np.sum(np.abs(b[m]) ** 2))
        rows.append(f"m={m:+d}: power {pw:.1e}, rel. diff {d:.1e}")
    print("   " + "\n   ".join(rows))

# The same difference against l, for the largest of the inexact m's (m = -1 and m = -3) at the last offset:
# the relabelling's error is largest at low l, where the sky's power is.
for m in (-1, -3):
    l = np.arange(abs(m), LS + 1)
    r = np.abs(a[m] - b[m]) / np.maximum(np.abs(b[m]), 1e-300)
    pick = [x for x in (2, 3, 5, 10, 30, 100, 300, 500) if x >= abs(m)]
    print(f"offset {off} deg, m = {m}: |MC - exact| / |exact| at l = " +
          ", ".join(f"{x}: {r[x - abs(m)]:.1e}" for x in pick))
