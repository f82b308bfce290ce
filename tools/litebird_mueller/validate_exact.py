"""Checks of the exact reference (common.ExactMuellerConvolver) before it is trusted:
(1) identity Mueller matrix: it must reproduce ducc0's plain Interpolator (the synthesis/analysis
round trip); (2) an on-axis round polarized Gaussian (m = 0 and +-2 only) with the ideal plate: there the
m-shift of MuellerConvolver is exact (d^l_{-2,-2} = d^l_{2,2}), so exact and litebird_sim must agree;
(3) the same with the generic plate, on a sky with a monopole and dipole (make_sky's default): the
monopole's leakage through M_QI, M_UI, which MuellerConvolver loses (monopole_check.py), and on the
same sky without l < 2: only the spin-0/spin-2 window of the T<->P entries (2 sigma^2 times them) is left."""
import numpy as np, healpy as hp
from common import *
from conftest import gaussian_blm

tm = Timer()
LS, LB, MM = 512, 768, 12
slm, _ = make_sky(LS, 64)
theta, phi, psi, alpha, near = make_pointings(4000)
ptg = ptg_array(theta, phi, psi)
blm = beam_blm(LB, MM, 0.3)
cut = resize_blm(blm, LB, MM, LS, MM)
plain = interp_plain(slm, cut, LS, MM, ptg)
ex, im = exact_conv(slm, blm, LB, MM, LS, np.eye(4), ptg, alpha)
print(f"(1) identity Mueller, off-axis beam 0.3 deg: exact vs Interpolator {fmt(stats(ex, plain))}; max imag {im:.1e}")
mcI = mueller_conv(slm, cut, LS, MM, np.eye(4), ptg, alpha)
print(f"    litebird MuellerConvolver(identity) vs Interpolator {fmt(stats(mcI, plain))}")
g = gaussian_blm(LB, np.radians(1.0))
gcut = resize_blm(g, LB, 2, LS, 2)
# MuellerConvolver needs kmax <= lmax - 4 and pads to kmax + 4
for name, M in (("ideal", IDEAL), ("generic", GENERIC)):
    mc = mueller_conv(slm, gcut, LS, 2, M, ptg, alpha)
    ex, im = exact_conv(slm, g, LB, 2, LS, M, ptg, alpha)
    print(f"({2 if name == 'ideal' else 3}) on-axis round Gaussian 1 deg, {name} plate, sky with monopole+dipole: MuellerConvolver vs exact {fmt(stats(mc, ex, near))}; max imag {im:.1e}")
s0, _ = make_sky(LS, 64, monopole=False)
mc = mueller_conv(s0, gcut, LS, 2, GENERIC, ptg, alpha)
ex, _ = exact_conv(s0, g, LB, 2, LS, GENERIC, ptg, alpha)
print(f"(3b) the same, generic plate, sky without l < 2: MuellerConvolver vs exact {fmt(stats(mc, ex, near))}")
print(f"time {tm():.0f} s")
