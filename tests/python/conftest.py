"""Shared pieces of the Python package's tests (run through ctest label `python`: run_pytest.py)."""

import numpy as np
import pytest


def smooth_sky_alm(lmax, seed, smoothing_fwhm):
    """A band-limited polarized sky as healpy a_lm (T, E, B): C_l ~ 1 / (l (l + 1)), E at 0.3 and B at
    0.1 of T, smoothed by a Gaussian of `smoothing_fwhm` (radians), no monopole."""
    import healpy as hp

    ell = np.arange(lmax + 1)
    cl = np.zeros(lmax + 1)
    cl[2:] = 1.0 / (ell[2:] * (ell[2:] + 1.0))
    window = hp.gauss_beam(smoothing_fwhm, lmax=lmax) ** 2
    np.random.seed(seed)
    alm = np.array([hp.synalm(cl * f * window, lmax=lmax) for f in (1.0, 0.3, 0.1)])
    alm[:, hp.Alm.getidx(lmax, 0, 0)] = 0
    return alm


def gaussian_blm(lmax, fwhm, epsilon=0.0, sign=1.0):
    """A Gaussian beam polarized along its frame's x axis as the (T, E, B) a_lm (mmax = 2) that ducc0's
    total convolution takes, TOAST's and litebird_sim's convention (-sqrt 2 on E and B): with it,
    ducc0 returns (1 + epsilon) I + (1 - epsilon)(Q cos 2psi + U sin 2psi) of the smoothed sky.
    sign = -1 turns the polarization by 90 deg (the B detector of a pair in its A's frame)."""
    import healpy as hp

    ell = np.arange(lmax + 1)
    bl = hp.gauss_beam(fwhm, lmax=lmax, pol=True)
    blm = np.zeros((3, hp.Alm.getsize(lmax, 2)), dtype=np.complex128)
    blm[0, hp.Alm.getidx(lmax, ell, 0)] = np.sqrt((2 * ell + 1) / (4 * np.pi)) * bl[:, 0] * (1 + epsilon)
    lp = ell[2:]
    e = np.sqrt((2 * lp + 1) / (32 * np.pi)) * bl[2:, 1] * (1 - epsilon) * sign
    blm[1, hp.Alm.getidx(lmax, lp, 2)] = -np.sqrt(2) * e
    blm[2, hp.Alm.getidx(lmax, lp, 2)] = -np.sqrt(2) * 1j * e
    return blm


def relative_rms(test, reference):
    test, reference = np.asarray(test), np.asarray(reference)
    return float(np.sqrt(np.mean((test - reference) ** 2) / np.mean(reference**2)))


@pytest.fixture
def tmp_out(tmp_path):
    return tmp_path
