"""A second, separate litebird_sim 0.18 MuellerConvolver effect (not the 8e-4): with a plate whose M_QI, M_UI
are non-zero (the generic plate), the sky's monopole (and dipole) leaks into the TOD modulated at 2 alpha.
MuellerConvolver builds the T row's effective beam from the beam's spin +-2 coefficients relabelled to
(l, m -+ 2) with the same l, so its effective T beam has nothing at l = 0, 1: the leakage of I's l = 0, 1
is lost. Sky: I = 1 everywhere; beam on its axis (round 1 deg Gaussian, polarized along x); 2000 samples."""
import numpy as np, healpy as hp
import pisco
from common import GENERIC, IDEAL, exact_conv, make_pointings, mueller_conv, pisco_tod, ptg_array, fmt, stats
from conftest import gaussian_blm
LS, LB, NSIDE = 512, 768, 256
slm = np.zeros((3, hp.Alm.getsize(LS)), complex); slm[0, 0] = np.sqrt(4 * np.pi)
sky = pisco.Sky.from_maps(hp.alm2map(slm, NSIDE, lmax=LS, pol=True))
theta, phi, psi, alpha, near = make_pointings(2000)
ptg = ptg_array(theta, phi, psi)
g = gaussian_blm(LB, np.radians(1.0))
from pisco._blm import resize_blm
mc = mueller_conv(slm, resize_blm(g, LB, 2, LS, 2), LS, 2, GENERIC, ptg, alpha)
ex, _ = exact_conv(slm, g, LB, 2, LS, GENERIC, ptg, alpha)
ours, _ = pisco_tod(sky, g, LB, 2, theta, phi, psi, alpha=alpha, mueller=GENERIC, grid_step=np.radians(1) / 40)
# the plate equation at the beam centre: detector reads (I + Q)-row of R(-a) M0 R(a) applied to (1, 0, 0, 0)
def rot(a):
    c, s = np.cos(2 * a), np.sin(2 * a)
    return np.array([[1, 0, 0, 0], [0, c, s, 0], [0, -s, c, 0], [0, 0, 0, 1]])
point = np.array([(rot(-a) @ GENERIC @ rot(a))[0, 0] + (rot(-a) @ GENERIC @ rot(a))[1, 0] for a in alpha])
for name, t in (("MuellerConvolver", mc), ("exact", ex), ("pisco", ours), ("M(alpha) at the beam centre", point)):
    print(f"I = 1 sky, generic plate: {name:28s} mean {t.mean():.5f}, std over alpha {t.std():.2e}")
print(f"MuellerConvolver vs exact: {fmt(stats(mc, ex))}; pisco vs exact: {fmt(stats(ours, ex))}")
