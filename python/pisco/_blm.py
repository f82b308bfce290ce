"""The frameworks' harmonic beams (b_lm) as PISCO-VK's detector beams (docs/python.md, "Beams from the
frameworks").

TOAST's ``SimTotalconvolve`` and litebird_sim's ``add_convolved_sky_to_observations`` hand ducc0's total
convolution b_lm (T, E, B in healpy's layout) expressed in a detector's beam frame, the detector's
polarization direction already in them: ducc0 sums them with the sky's a_lm as they are. In PISCO-VK a
beamsor's Mueller rows are in the detector's own basis, the antenna basis turned by its zeta. The beam
of a detector at zeta is therefore ``Beamsor.from_blm(b_lm exp(i m zeta), angle=zeta)``: the
coefficients turned by -zeta, then the whole beam turned back by zeta, so that its pattern stays where
the file has it and its Stokes parameters are in the detector's basis. With epsilon 0 and gain 1 the
engine's TOD is then ducc0's sum divided by 2 Omega~ (``beam.omega_tilde``).
"""

import os

import numpy as np

from ._pisco import Beamsor

__all__ = ["alm_m", "read_blm_file", "resize_blm", "detector_beam"]


def alm_m(lmax, mmax):
    """m of each coefficient of healpy's layout (m-major: m = 0..mmax, l = m..lmax)."""
    return np.concatenate([np.full(lmax - m + 1, m, dtype=np.float64) for m in range(mmax + 1)])


def alm_size(lmax, mmax):
    return (mmax + 1) * (lmax + 1) - mmax * (mmax + 1) // 2


def resize_blm(blm, lmax, mmax, lmax_out, mmax_out):
    """The rows of `blm` (lmax, mmax) truncated or padded with zeros to (lmax_out, mmax_out), as
    healpy's resize_alm and the frameworks' readers do."""
    blm = np.asarray(blm)
    out = np.zeros((blm.shape[0], alm_size(lmax_out, mmax_out)), dtype=np.complex128)
    lmin = min(lmax, lmax_out)
    i = o = 0
    for m in range(min(mmax, mmax_out) + 1):
        n = lmin - m + 1
        if n > 0:
            out[:, o : o + n] = blm[:, i : i + n]
        i += lmax - m + 1
        o += lmax_out - m + 1
    return out


def read_blm_file(path):
    """(b_lm, lmax, mmax) of a healpy alm FITS file: T alone (one HDU) or T, E, B (HDUs 1 to 3, as
    TOAST's SimTotalconvolve reads them), each padded to the largest lmax and mmax among them."""
    import healpy as hp
    from astropy.io import fits

    path = os.fspath(path)
    with fits.open(path) as f:
        n_hdu = len(f) - 1
    if n_hdu < 1:
        raise ValueError(f"{path}: no a_lm extension (expected T, or T, E, B in HDUs 1 to 3)")
    parts = []
    for hdu in range(1, 4 if n_hdu >= 3 else 2):
        alm, mmax = hp.read_alm(path, hdu=hdu, return_mmax=True)
        parts.append((np.asarray(alm, dtype=np.complex128), hp.Alm.getlmax(len(alm), mmax), mmax))
    lmax = max(p[1] for p in parts)
    mmax = max(p[2] for p in parts)
    blm = np.concatenate([resize_blm(a[None, :], l, m, lmax, mmax) for a, l, m in parts])
    if not np.all(np.isfinite(blm)):
        raise ValueError(f"{path}: the b_lm are not finite")
    return blm, lmax, mmax


def detector_beam(blm, lmax, mmax, zeta, rho_max, grid_step=0.0, half_turn=False):
    """The beamsor of a detector at `zeta` whose b_lm (ducc0's convention: its beam frame, its
    polarization direction in them) are `blm`: from_blm(b_lm exp(i m zeta), angle=zeta).
    half_turn: the b_lm's frame is the antenna frame turned by 180 deg about the line of sight (TOAST's
    SimTotalconvolve hands ducc0 psi + pi), so that they are first turned by 180 deg: b_lm (-1)^m."""
    blm = np.asarray(blm, dtype=np.complex128)
    if blm.ndim == 1:
        blm = blm[None, :]
    m = alm_m(lmax, mmax)
    turned = blm * np.exp(1j * zeta * m)
    if half_turn:
        turned *= np.where(m % 2 == 1, -1.0, 1.0)
    return Beamsor.from_blm(turned, rho_max=rho_max, grid_step=grid_step, angle=zeta, lmax=lmax, mmax=mmax)
