"""One thing varied at a time, for the off-axis beam of the hand check (0.3 deg off its axis; and 2 deg
where it matters), ideal plate unless said: see offaxis_hwp.py for the set-up.
Figures: relative RMS and max |diff| / RMS of the reference over 4000 samples (360 within 10 deg of a pole).
Usage: python variants.py [A B C ...]   (default: all)"""
import sys

import numpy as np
import healpy as hp

import pisco
from common import (GENERIC, IDEAL, Timer, beam_blm, exact_conv, fmt, interp_plain, make_pointings, make_sky,
                    mueller_conv, pisco_tod, ptg_array, resize_blm, stats)

which = set(sys.argv[1:]) or set("ABCDEFGHI")
tm = Timer()
NSIDE, LS, LB, MM = 256, 512, 768, 12
FWHM = np.radians(1.0)
slm, maps = make_sky(LS, NSIDE, monopole=False)
sky = pisco.Sky.from_maps(maps)
theta, phi, psi, alpha, near = make_pointings(4000)
ptg = ptg_array(theta, phi, psi)
_beams = {}


def beam(off, mmax=MM):
    if (off, mmax) not in _beams:
        _beams[(off, mmax)] = beam_blm(LB, mmax, off)
    return _beams[(off, mmax)]


def line(label, s):
    print(f"  {label:58s} {fmt(s)}", flush=True)


def refs(off, M=IDEAL, mmax=MM, s=slm):
    b = beam(off, mmax)
    cut = resize_blm(b, LB, mmax, LS, mmax)
    return mueller_conv(s, cut, LS, mmax, M, ptg, alpha), exact_conv(s, b, LB, mmax, LS, M, ptg, alpha)[0]


if "A" in which:
    print("A. the sky's multipoles: MuellerConvolver vs exact, ideal plate, offset 0.3 deg")
    for lmin in (0, 10, 30, 100):
        s = slm.copy()
        for m in range(0, min(lmin, LS + 1)):
            for l in range(m, lmin):
                s[:, hp.Alm.getidx(LS, l, m)] = 0
        mc, ex = refs(0.3, s=s)
        line(f"sky l >= {lmin}", stats(mc, ex, near))
    s = slm.copy(); s[0] = 0
    mc, ex = refs(0.3, s=s)
    line("sky Q, U only (I = 0)", stats(mc, ex, near))
    s = slm.copy(); s[1:] = 0
    mc, ex = refs(0.3, s=s)
    line("sky I only (Q = U = 0)", stats(mc, ex, near))
    print(f"  ({tm():.0f} s)")

if "B" in which:
    print("B. the b_lm's mmax (both sides from the same truncated b_lm)")
    for off in (0.3, 2.0):
        truth = None
        for mmax in (20, 12, 8):
            mc, ex = refs(off, mmax=mmax)
            ours, _ = pisco_tod(sky, beam(off, mmax), LB, mmax, theta, phi, psi, alpha=alpha, mueller=IDEAL,
                                grid_step=FWHM / 40)
            line(f"offset {off}, mmax {mmax}: MuellerConvolver vs exact", stats(mc, ex, near))
            line(f"offset {off}, mmax {mmax}: pisco(FWHM/40) vs exact", stats(ours, ex, near))
            if truth is None:
                truth = ex
            else:
                line(f"offset {off}, mmax {mmax}: exact vs exact at mmax 20 (the cut)", stats(ex, truth, near))
    print(f"  ({tm():.0f} s)")

if "C" in which:
    print("C. PISCO-VK's rho_max (FWHM/40), ideal plate, against exact")
    for off in (0.3, 2.0):
        _, ex = refs(off)
        for rho in (2.0, 3.0, 4.0, 5.0, 7.0):
            ours, _ = pisco_tod(sky, beam(off), LB, MM, theta, phi, psi, alpha=alpha, mueller=IDEAL,
                                rho_max_deg=rho, grid_step=FWHM / 40)
            line(f"offset {off}, rho_max {rho} deg", stats(ours, ex, near))
    print(f"  ({tm():.0f} s)")

if "D" in which:
    print("D. PISCO-VK's grid step, ideal plate, offset 0.3 deg")
    mc, ex = refs(0.3)
    for div in (0, 40, 80):
        ours, b = pisco_tod(sky, beam(0.3), LB, MM, theta, phi, psi, alpha=alpha, mueller=IDEAL,
                            grid_step=FWHM / div if div else 0.0)
        lab = f"step {np.degrees(b.grid_step) * 60:.2f} arcmin" + (" (default 0.6/l_eff)" if not div else f" (FWHM/{div})")
        line(f"{lab}: pisco vs exact", stats(ours, ex, near))
        line(f"{lab}: pisco vs MuellerConvolver", stats(ours, mc, near))
    print(f"  ({tm():.0f} s)")

if "E" in which:
    print("E. MuellerConvolver's own parameters, offset 0.3 deg, ideal plate, against exact")
    b = beam(0.3)
    cut = resize_blm(b, LB, MM, LS, MM)
    ex = exact_conv(slm, b, LB, MM, LS, IDEAL, ptg, alpha)[0]
    for eps, nt in ((1e-9, 2), (1e-9, 1), (1e-8, 2), (1e-5, 2)):
        mc = mueller_conv(slm, cut, LS, MM, IDEAL, ptg, alpha, epsilon=eps, nthreads=nt)
        line(f"epsilon {eps:g}, nthreads {nt}", stats(mc, ex, near))
    ex12 = exact_conv(slm, b, LB, MM, LS, IDEAL, ptg, alpha, mask_deg=12.0)[0]
    line("(exact: beam fields masked beyond 12 deg instead of 30)", stats(ex12, ex, near))
    ex0 = exact_conv(slm, b, LB, MM, LS, IDEAL, ptg, alpha, mask_deg=None)[0]
    line("(exact: no mask)", stats(ex0, ex, near))
    print(f"  ({tm():.0f} s)")

if "F" in which:
    print("F. the detector's pol_angle_rad zeta (the adapter's turn b_lm e^{i m zeta}, angle = zeta, gamma = zeta)")
    mc, ex = refs(0.3)
    for zdeg in (22.5, 90.0):
        ours, _ = pisco_tod(sky, beam(0.3), LB, MM, theta, phi, psi, alpha=alpha, mueller=IDEAL,
                            zeta=np.radians(zdeg), grid_step=FWHM / 40)
        line(f"zeta {zdeg} deg: pisco vs exact", stats(ours, ex, near))
        line(f"zeta {zdeg} deg: pisco vs MuellerConvolver", stats(ours, mc, near))
    print(f"  ({tm():.0f} s)")

if "G" in which:
    print("G. conventions: PISCO-VK (FWHM/40) with one sign changed, against exact (offset 0.3, ideal plate)")
    _, ex = refs(0.3)
    b = beam(0.3)
    ours, _ = pisco_tod(sky, b, LB, MM, theta, phi, psi, alpha=-alpha, mueller=IDEAL, grid_step=FWHM / 40)
    line("plate angle -alpha", stats(ours, ex, near))
    ours, _ = pisco_tod(sky, b, LB, MM, theta, phi, -psi, alpha=alpha, mueller=IDEAL, grid_step=FWHM / 40)
    line("psi -> -psi", stats(ours, ex, near))
    flipped = b.copy(); flipped[1:] *= -1
    ours, _ = pisco_tod(sky, flipped, LB, MM, theta, phi, psi, alpha=alpha, mueller=IDEAL, grid_step=FWHM / 40)
    line("beam polarization turned by 90 deg (E, B -> -E, -B)", stats(ours, ex, near))
    ours, _ = pisco_tod(sky, b, LB, MM, theta, phi, psi, alpha=alpha, mueller=IDEAL, grid_step=FWHM / 40,
                        placement="detector")
    line("plate between optics and detector (placement='detector')", stats(ours, ex, near))
    print(f"  ({tm():.0f} s)")

if "H" in which:
    print("H. a sky with a monopole (I = 3) and a dipole, offset 0.3 deg")
    s2, maps2 = make_sky(LS, NSIDE, monopole=True)
    sky2 = pisco.Sky.from_maps(maps2)
    for name, M in (("ideal", IDEAL), ("generic", GENERIC)):
        b = beam(0.3)
        cut = resize_blm(b, LB, MM, LS, MM)
        mc = mueller_conv(s2, cut, LS, MM, M, ptg, alpha)
        ex = exact_conv(s2, b, LB, MM, LS, M, ptg, alpha)[0]
        ours, _ = pisco_tod(sky2, b, LB, MM, theta, phi, psi, alpha=alpha, mueller=M, grid_step=FWHM / 40)
        line(f"{name}: MuellerConvolver vs exact", stats(mc, ex, near))
        line(f"{name}: pisco(FWHM/40) vs exact", stats(ours, ex, near))
    # the same with the beam on its axis: the generic plate's M_QI, M_UI on the monopole
    b0 = beam(0.0)
    cut0 = resize_blm(b0, LB, MM, LS, MM)
    mc = mueller_conv(s2, cut0, LS, MM, GENERIC, ptg, alpha)
    ex = exact_conv(s2, b0, LB, MM, LS, GENERIC, ptg, alpha)[0]
    ours, _ = pisco_tod(sky2, b0, LB, MM, theta, phi, psi, alpha=alpha, mueller=GENERIC, grid_step=FWHM / 40)
    line("generic, beam on its axis: MuellerConvolver vs exact", stats(mc, ex, near))
    line("generic, beam on its axis: pisco(FWHM/40) vs exact", stats(ours, ex, near))
    print(f"  ({tm():.0f} s)")

if "I" in which:
    print("I. NSIDE 128 (sky lmax 256), offset 0.3 deg, ideal plate")
    s3, maps3 = make_sky(256, 128, monopole=False)
    sky3 = pisco.Sky.from_maps(maps3)
    b = beam(0.3)
    cut = resize_blm(b, LB, MM, 256, MM)
    mc = mueller_conv(s3, cut, 256, MM, IDEAL, ptg, alpha)
    ex = exact_conv(s3, b, LB, MM, 256, IDEAL, ptg, alpha)[0]
    ours, _ = pisco_tod(sky3, b, LB, MM, theta, phi, psi, alpha=alpha, mueller=IDEAL, grid_step=FWHM / 40)
    line("MuellerConvolver vs exact", stats(mc, ex, near))
    line("pisco(FWHM/40) vs exact", stats(ours, ex, near))
    line("pisco(FWHM/40) vs MuellerConvolver", stats(ours, mc, near))
    print(f"  ({tm():.0f} s)")
print(f"total {tm():.0f} s")
