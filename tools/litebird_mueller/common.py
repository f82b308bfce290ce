"""Shared pieces of the off-axis b_lm comparisons (tools/litebird_mueller): sky, beams, pointings, the three
harmonic evaluations (ducc0 Interpolator, litebird_sim's MuellerConvolver, and the exact real-space
version of MuellerConvolver with PISCO-VK's pixel-space convolution, both from
tests/python/mueller_reference.py, which test_litebird.py uses too).

Run with PYTHONPATH=build/python:tests/python and build/python-venv/bin/python (see README.md)."""

import time

import numpy as np
import healpy as hp
import ducc0

import pisco
from pisco._blm import detector_beam, resize_blm
from conftest import offset_elliptical_blm, smooth_sky_alm
from litebird_sim.mueller_convolver import MuellerConvolver, mueller_to_C
from mueller_reference import (GENERIC, IDEAL, NTHREADS, ExactMuellerConvolver, exact_conv, mueller_conv,  # noqa: F401
                               nalm, pisco_tod, ptg_array)


def stats(test, ref, near=None):
    """relative RMS and max |diff| / RMS(ref), and the same within `near` if given."""
    d = np.asarray(test) - np.asarray(ref)
    r = np.sqrt(np.mean(np.asarray(ref) ** 2))
    out = dict(rms=float(np.sqrt(np.mean(d ** 2)) / r), max=float(np.max(np.abs(d)) / r))
    if near is not None and np.any(near):
        out["rms_poles"] = float(np.sqrt(np.mean(d[near] ** 2)) / r)
    return out


def fmt(s):
    t = f"rms {s['rms']:.2e}  max {s['max']:.2e}"
    if "rms_poles" in s:
        t += f"  (poles rms {s['rms_poles']:.2e})"
    return t


def make_sky(lmax, nside, seed=5, monopole=True):
    alm = smooth_sky_alm(lmax, seed=seed, smoothing_fwhm=np.radians(0.5))
    if monopole:
        alm[0, hp.Alm.getidx(lmax, 0, 0)] = 3.0 * np.sqrt(4 * np.pi)  # I = 3
        alm[0, hp.Alm.getidx(lmax, 1, 0)] = 0.5
    maps = hp.alm2map(alm, nside, lmax=lmax, pol=True)
    return alm, maps


def make_pointings(n, seed=4, n_polar=300):
    rng = np.random.default_rng(seed)
    theta = np.arccos(rng.uniform(-1, 1, n))
    k = n_polar // 2
    theta[:k] = rng.uniform(0, np.radians(3), k)
    theta[k:2 * k] = np.pi - rng.uniform(0, np.radians(3), k)
    phi = rng.uniform(0, 2 * np.pi, n)
    psi = rng.uniform(-np.pi, np.pi, n)
    alpha = rng.uniform(0, 2 * np.pi, n)
    near = np.minimum(theta, np.pi - theta) < np.radians(10)
    return theta, phi, psi, alpha, near


def beam_blm(lmax, mmax, offset_deg, fwhm_deg=1.0, ellipticity=1.5, psi_ell_deg=25.0, xpol=0.02,
             offset_angle_deg=40.0):
    return offset_elliptical_blm(lmax, mmax, np.radians(fwhm_deg), ellipticity, np.radians(psi_ell_deg),
                                 psi_pol=0.0, cross_polar_leakage=xpol, offset=np.radians(offset_deg),
                                 offset_angle=np.radians(offset_angle_deg))


def interp_plain(slm, blm, lmax, kmax, ptg, epsilon=1e-9):
    """ducc0's total convolution (litebird_sim's path without a plate): beam cut to (lmax, kmax)."""
    inter = ducc0.totalconvolve.Interpolator(slm, blm, False, lmax, kmax, epsilon=epsilon, nthreads=NTHREADS,
                                             npoints=len(ptg))
    return inter.interpol(ptg)[0]


class Timer:
    def __init__(self):
        self.t0 = time.time()

    def __call__(self):
        return time.time() - self.t0
