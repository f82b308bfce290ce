"""Off-axis b_lm beams through litebird_sim's MuellerConvolver, an exact harmonic reference and PISCO-VK.

For each beam offset: an elliptical polarized Gaussian (FWHM 1 deg, ellipticity 1.5, major axis at 25 deg,
cross-polar leakage 0.02; conftest.offset_elliptical_blm, lmax 768, mmax 12) moved `offset` off its
axis; a band-limited polarized sky (lmax 512; NSIDE 256 map for PISCO-VK); N random pointings (300
within 3 deg of the poles) and random plate angles. Evaluations:
  plain   ducc0 Interpolator (litebird_sim's path without a plate), beam cut to (512, 12)
  MC      litebird_sim 0.18 MuellerConvolver (ideal / generic plate), beam cut to (512, 12), epsilon 1e-9
  exact   common.ExactMuellerConvolver: MuellerConvolver's algebra with the m shifts done in real space
  pisco   PISCO-VK cpu, plate at the aperture, the litebird adapter's recipe (detector_beam, gain 2 Omega~)
Printed: relative RMS and max |diff| / RMS of the reference.

Usage: python offaxis_hwp.py [--offsets 0 0.3 0.5 1 2] [--n 4000] [--monopole] [--fine 40]
"""
import argparse

import numpy as np
import healpy as hp

import pisco
from common import (GENERIC, IDEAL, Timer, beam_blm, exact_conv, fmt, interp_plain, make_pointings, make_sky,
                    mueller_conv, pisco_tod, ptg_array, resize_blm, stats)

p = argparse.ArgumentParser()
p.add_argument("--offsets", type=float, nargs="+", default=[0.0, 0.3, 0.5, 1.0, 2.0])
p.add_argument("--n", type=int, default=4000)
p.add_argument("--nside", type=int, default=256)
p.add_argument("--monopole", action="store_true", help="add I = 3 and a dipole to the sky")
p.add_argument("--fine", type=float, default=40.0, help="PISCO-VK's fine grid step: FWHM / this")
p.add_argument("--rho", type=float, default=5.0, help="PISCO-VK's rho_max, deg")
p.add_argument("--plates", nargs="+", default=["ideal", "generic"])
p.add_argument("--mmax", type=int, default=12)
p.add_argument("--zeta", type=float, default=0.0, help="detector's pol_angle_rad, deg (the adapter's turn)")
args = p.parse_args()

tm = Timer()
LS, LB, MM, NSIDE = 2 * args.nside, 768, args.mmax, args.nside
slm, maps = make_sky(LS, NSIDE, monopole=args.monopole)
sky = pisco.Sky.from_maps(maps)
theta, phi, psi, alpha, near = make_pointings(args.n)
ptg = ptg_array(theta, phi, psi)
fine = np.radians(1.0) / args.fine
zeta = np.radians(args.zeta)
plates = {"ideal": IDEAL, "generic": GENERIC}
print(f"sky lmax {LS} (NSIDE {NSIDE} for PISCO-VK), monopole+dipole: {args.monopole}; beam lmax {LB}, mmax {MM}; "
      f"{args.n} samples ({near.sum()} within 10 deg of a pole); PISCO-VK rho_max {args.rho} deg, fine step FWHM/"
      f"{args.fine:g}; zeta {args.zeta} deg")
for off in args.offsets:
    blm = beam_blm(LB, MM, off)
    cut = resize_blm(blm, LB, MM, LS, MM)
    plain = interp_plain(slm, cut, LS, MM, ptg)
    ours, beam = pisco_tod(sky, blm, LB, MM, theta, phi, psi, zeta=zeta, rho_max_deg=args.rho, grid_step=fine)
    print(f"offset {off:.2f} deg:")
    print(f"  no plate   pisco(FWHM/{args.fine:g}) vs Interpolator: {fmt(stats(ours, plain, near))}")
    for name in args.plates:
        M = plates[name]
        mc = mueller_conv(slm, cut, LS, MM, M, ptg, alpha)
        ex, im = exact_conv(slm, blm, LB, MM, LS, M, ptg, alpha)
        ex_cut, _ = exact_conv(slm, cut, LS, MM, LS, M, ptg, alpha)
        ours, _ = pisco_tod(sky, blm, LB, MM, theta, phi, psi, alpha=alpha, mueller=M, zeta=zeta,
                            rho_max_deg=args.rho, grid_step=fine)
        ours_d, bd = pisco_tod(sky, blm, LB, MM, theta, phi, psi, alpha=alpha, mueller=M, zeta=zeta,
                               rho_max_deg=args.rho, grid_step=0.0)
        print(f"  {name:8s} pisco(FWHM/{args.fine:g}) vs MuellerConvolver: {fmt(stats(ours, mc, near))}")
        print(f"  {name:8s} pisco(FWHM/{args.fine:g}) vs exact          : {fmt(stats(ours, ex, near))}")
        print(f"  {name:8s} pisco(default {np.degrees(bd.grid_step) * 60:.2f}') vs exact   : {fmt(stats(ours_d, ex, near))}")
        print(f"  {name:8s} MuellerConvolver vs exact            : {fmt(stats(mc, ex, near))}")
        print(f"  {name:8s} exact(beam cut to l<={LS}) vs exact  : {fmt(stats(ex_cut, ex, near))}   [max imag {im:.0e}]")
    print(f"  ({tm():.0f} s)", flush=True)
print(f"total {tm():.0f} s")
