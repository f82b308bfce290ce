"""litebird_sim's MuellerConvolver with its effective beams made exactly, the reference that tells its
approximation from ours (docs/python.md, "litebird_sim's Mueller convolver"), and the pieces that
call MuellerConvolver and PISCO-VK alike. Used by test_litebird.py and tools/litebird_mueller.

Needs ducc0 and litebird_sim (the tests' environment, tests/python/python_env.py)."""

import numpy as np
import ducc0

import pisco
from pisco._blm import detector_beam, resize_blm
from litebird_sim.mueller_convolver import MuellerConvolver, mueller_to_C

NTHREADS = 2
IDEAL = np.diag([1.0, 1.0, -1.0, -1.0])
# The ideal plate plus leakage in all 16 entries, a 2% loss in M_II keeping it passive
# (tools/hwp_compare.py's generic plate).
GENERIC = IDEAL + np.array([[-0.02, 0.012, -0.008, 0.005],
                            [0.021, -0.03, 0.017, -0.011],
                            [-0.015, 0.009, 0.025, 0.04],
                            [0.007, -0.02, 0.033, 0.02]])


def nalm(lmax, mmax):
    return ((mmax + 1) * (mmax + 2)) // 2 + (mmax + 1) * (lmax - mmax)


def ptg_array(theta, phi, psi):
    return np.ascontiguousarray(np.stack([theta, np.mod(phi, 2 * np.pi), psi], axis=1))


def mueller_conv(slm, blm, lmax, kmax, mueller, ptg, alpha, epsilon=1e-9, nthreads=NTHREADS):
    """litebird_sim 0.18's MuellerConvolver as litebird_sim calls it (blm already cut to (lmax, kmax));
    npoints = the number of samples (memory only; litebird_sim leaves its default 1e9)."""
    mc = MuellerConvolver(slm=slm, blm=blm, mueller=mueller, lmax=lmax, kmax=kmax, single_precision=False,
                          epsilon=epsilon, nthreads=nthreads, npoints=len(ptg))
    return mc.signal(ptg=ptg, alpha=alpha, strict_typing=False)


class ExactMuellerConvolver(MuellerConvolver):
    """MuellerConvolver with its effective beams made exactly: the same algebra (Duivenvoorden et al.
    2021 as litebird_sim 0.18 codes it), but each shift of m by +-2 or +-4 applied as what it stands
    for, a multiplication of the beam's real-space field by exp(-+2i phi) or exp(-+4i phi) (the turn
    between the beam frame's polar basis and its Cartesian, Ludwig-3, basis), followed by an exact
    spin-0 / spin-2 analysis (Gauss-Legendre grid). MuellerConvolver instead relabels the
    coefficients (l, m) -> (l, m -+ 2) and changes their spin, which keeps the l of every coefficient:
    d^l_{m,-s}(theta) -> d^l_{m-+k,-s'}(theta), the flat-sky approximation.

    blm_full, lmax_full, mmax_full: the beam before any cut in l (the effective beam is analysed up
    to lmax_full and then cut to the convolution's lmax); mask_deg: the beam fields are set to 0 beyond
    this colatitude (the truncated b_lm's ringing; the L3 basis is singular at the antipode)."""

    def __init__(self, *, blm_full, lmax_full, mmax_full, mask_deg=30.0, ntheta=None, **kw):
        self._full = (np.asarray(blm_full), lmax_full, mmax_full)
        self._mask = np.radians(mask_deg) if mask_deg else None
        self._ntheta = ntheta
        self.max_imag = 0.0
        super().__init__(**kw)

    def _mueller_tc_prep(self, blm, mueller, lmax, mmax):
        bfull, L, M = self._full
        assert M == mmax, (M, mmax)
        C = mueller_to_C(mueller)
        mout = mmax + 4
        nth = self._ntheta or max(2 * L, 2 * lmax) + 2
        nph = 2 * (mout + 8) + 2
        theta = ducc0.misc.GL_thetas(nth)
        phi = 2 * np.pi * np.arange(nph) / nph
        eiphi = np.exp(1j * phi)[None, :]
        T = ducc0.sht.synthesis_2d(alm=bfull[0:1], spin=0, lmax=L, mmax=M, geometry="GL", ntheta=nth, nphi=nph,
                                   nthreads=NTHREADS)[0]
        QU = ducc0.sht.synthesis_2d(alm=np.ascontiguousarray(bfull[1:3]), spin=2, lmax=L, mmax=M, geometry="GL",
                                    ntheta=nth, nphi=nph, nthreads=NTHREADS)
        if self._mask is not None:
            keep = (theta <= self._mask)[:, None]
            T = T * keep
            QU = QU * keep[None]
        Pp = QU[0] + 1j * QU[1]
        Pm = QU[0] - 1j * QU[1]
        s2 = np.sqrt(2.0)
        res = np.zeros((5, 3, nalm(lmax, mout)), dtype=self._ctype)
        for ib in range(5):
            a = ib * np.pi / 5
            e2, e4 = np.exp(2j * a), np.exp(4j * a)
            effT = C[0, 0] * T + (C[1, 0] / e2 * eiphi ** 2 * Pp + C[2, 0] * e2 * eiphi ** -2 * Pm) / s2
            effPp = s2 * e2 * C[0, 1] * eiphi ** -2 * T + C[2, 1] * e4 * eiphi ** -4 * Pm + C[1, 1] * Pp
            effPm = s2 / e2 * C[0, 2] * eiphi ** 2 * T + C[1, 2] / e4 * eiphi ** 4 * Pp + C[2, 2] * Pm
            Qe = 0.5 * (effPp + effPm)
            Ue = (effPp - effPm) / 2j
            scale = max(np.abs(T).max(), 1e-300)
            self.max_imag = max(self.max_imag, np.abs(effT.imag).max() / scale, np.abs(Qe.imag).max() / scale,
                                np.abs(Ue.imag).max() / scale)
            t = ducc0.sht.analysis_2d(map=np.ascontiguousarray(effT.real[None]), spin=0, lmax=L, mmax=mout,
                                      geometry="GL", nthreads=NTHREADS)
            eb = ducc0.sht.analysis_2d(map=np.ascontiguousarray(np.stack([Qe.real, Ue.real])), spin=2, lmax=L,
                                       mmax=mout, geometry="GL", nthreads=NTHREADS)
            full = np.concatenate([t, eb])
            res[ib] = resize_blm(full, L, mout, lmax, mout)
        return res


def effective_beams(blm_full, lmax_full, mmax, lmax, mueller, mask_deg=30.0):
    """The effective beams (per plate angle: T, E, B coefficients to lmax and mmax + 4) that
    MuellerConvolver builds from the beam cut to (lmax, mmax), and that ExactMuellerConvolver builds from
    the whole beam, without their interpolators: (MuellerConvolver's, the exact ones)."""
    blm = resize_blm(blm_full, lmax_full, mmax, lmax, mmax)
    theirs = MuellerConvolver.__new__(MuellerConvolver)
    theirs._ctype = np.complex128
    exact = ExactMuellerConvolver.__new__(ExactMuellerConvolver)
    exact._full = (np.asarray(blm_full), lmax_full, mmax)
    exact._mask = np.radians(mask_deg)
    exact._ntheta = None
    exact.max_imag = 0.0
    exact._ctype = np.complex128
    return (MuellerConvolver._mueller_tc_prep(theirs, blm, mueller, lmax, mmax),
            exact._mueller_tc_prep(blm, mueller, lmax, mmax))


def pplus_by_m(eb, lmax, mmax):
    """{m: P+[l, m], l = |m|..lmax} for m in -mmax..mmax from healpy-layout E, B coefficients."""
    out, idx = {}, 0
    for m in range(mmax + 1):
        n = lmax - m + 1
        e, b = eb[0, idx:idx + n], eb[1, idx:idx + n]
        out[m] = -(e + 1j * b)
        out[-m] = (-1) ** m * np.conj(-(e - 1j * b))
        idx += n
    return out


def exact_conv(slm, blm_full, lmax_full, mmax, lmax, mueller, ptg, alpha, epsilon=1e-9, mask_deg=30.0):
    mc = ExactMuellerConvolver(blm_full=blm_full, lmax_full=lmax_full, mmax_full=mmax, mask_deg=mask_deg,
                               slm=slm, blm=resize_blm(blm_full, lmax_full, mmax, lmax, mmax), mueller=mueller,
                               lmax=lmax, kmax=mmax, single_precision=False, epsilon=epsilon, nthreads=NTHREADS,
                               npoints=len(ptg))
    return mc.signal(ptg=ptg, alpha=alpha, strict_typing=False), mc.max_imag


def pisco_tod(sky, blm, lmax, mmax, theta, phi, psi, alpha=None, mueller=None, zeta=0.0, rho_max_deg=5.0,
              grid_step=0.0, placement="aperture", backend="cpu"):
    """PISCO-VK through the litebird adapter's recipe: from_blm(b_lm e^{i m zeta}, angle=zeta), epsilon 0,
    gain 2 Omega~; the plate (if mueller is given) with gamma = zeta, hwp_angle = alpha."""
    beam = detector_beam(blm, lmax, mmax, zeta, np.radians(rho_max_deg), grid_step)
    fp = pisco.FocalPlane()
    plate = None if mueller is None else pisco.HalfWavePlate(mueller, placement=placement, gamma=zeta)
    fp.add("d", zeta=zeta, epsilon=0.0, gain=2 * beam.omega_tilde, hwp=plate)
    with pisco.Engine(sky, beam, fp, backend=backend) as engine:
        tod = engine.convolve(0, theta, phi, psi, hwp_angle=alpha if mueller is not None else None)
    return tod, beam
