#!/usr/bin/env python3
"""What a HEALPix map says near its poles, by ducc0's least-squares analysis (docs/physics.md, "The
quadrature"; docs/validation.md, "L").

1. A sky with power up to 3 NSIDE - 1 (a red spectrum, C_l = 1 / (1 + (l / 30)^2)): its a_lm from its
   map by map2alm with 3 Jacobi iterations (what a global transform gives) and by ducc0's
   pseudo_analysis (least squares, LSQR) with 100 and 1000 iterations, smoothed by a Gaussian beam of 6
   pixels per FWHM and compared with the exact smoothing of the true a_lm, worst per band of
   colatitude from the nearer pole, relative to the smoothed map's RMS. The map holds the smoothed sky
   at every colatitude, the poles included, to 1e-6 and better: what a local fit can reach.
2. One bright pixel at colatitudes 2, 5, 45 and 90 deg: the smoothing of its least-squares a_lm (its
   band-limited reading, 300 iterations) against the beam centred on the pixel (the pixel taken as a
   point), along the meridian through it, relative to the peak. The two readings differ by 2e-2 of
   the peak 2 deg from a pole and agree at the equator: near a pole no linear reading of a map can be
   both.

Run with the tests' environment (ducc0, healpy):
    build/python-venv/bin/python tools/pole_references.py [--nside 64]
"""
import argparse

import numpy as np


def band_limited_sky(nside):
    import ducc0
    import healpy as hp

    lmax = 3 * nside - 1
    cl = 1.0 / (1.0 + (np.arange(lmax + 1) / 30.0) ** 2)
    np.random.seed(2)
    alm = hp.synalm(cl, lmax=lmax, new=True)
    m = hp.alm2map(alm, nside, lmax=lmax)
    geom = ducc0.healpix.Healpix_Base(nside, "RING").sht_info()
    fwhm = 6 * np.sqrt(np.pi / 3) / nside
    bl = hp.gauss_beam(fwhm, lmax)
    hr = 4 * nside
    ref = hp.alm2map(hp.almxfl(alm, bl), hr, lmax=lmax)
    rms = np.std(ref)
    theta, _ = hp.pix2ang(hr, np.arange(12 * hr * hr))
    colat = np.degrees(np.minimum(theta, np.pi - theta))
    bands = [(0, 1), (1, 3), (3, 6), (6, 10), (10, 20), (20, 40), (40, 90)]
    print(f"1. NSIDE {nside}, power to l = {lmax}, beam of 6 pixels per FWHM: worst error of the smoothed map")
    print("   | a_lm from | " + " | ".join(f"{a}-{b} deg" for a, b in bands) + " |")
    print("   |---|" + "---|" * len(bands))
    for label, it in (("map2alm, 3 iterations", 0), ("pseudo_analysis, 100", 100), ("pseudo_analysis, 1000", 1000)):
        if it == 0:
            a = hp.map2alm(m, lmax=lmax, iter=3, use_weights=False)
        else:
            a = ducc0.sht.pseudo_analysis(map=m.reshape(1, -1), lmax=lmax, spin=0, maxiter=it, epsilon=1e-14,
                                          nthreads=0, **geom)[0][0]
        e = np.abs(hp.alm2map(hp.almxfl(a, bl), hr, lmax=lmax) - ref) / rms
        print(f"   | {label} | " + " | ".join(f"{e[(colat >= a_) & (colat < b_)].max():.1e}" for a_, b_ in bands) + " |")


def one_pixel(nside):
    import ducc0
    import healpy as hp

    lmax = 3 * nside - 1
    geom = ducc0.healpix.Healpix_Base(nside, "RING").sht_info()
    fwhm = 6 * np.sqrt(np.pi / 3) / nside
    sig = fwhm / np.sqrt(8 * np.log(2))
    r = np.linspace(0, 5 * fwhm, 20001)
    bl = hp.beam2bl(np.exp(-r ** 2 / (2 * sig ** 2)), r, lmax)
    area = 4 * np.pi / (12 * nside * nside)
    hr = 4 * nside
    print(f"2. NSIDE {nside}, one bright pixel: its band-limited reading against the pixel as a point")
    print("   | colatitude | worst difference / peak |")
    print("   |---|---|")
    for colat in (2.0, 5.0, 45.0, 90.0):
        p = hp.ang2pix(nside, np.radians(colat), 0.3)
        m = np.zeros(12 * nside * nside)
        m[p] = 1.0
        v = np.array(hp.pix2vec(nside, p))
        a = ducc0.sht.pseudo_analysis(map=m.reshape(1, -1), lmax=lmax, spin=0, maxiter=300, epsilon=1e-13, nthreads=0,
                                      **geom)[0][0]
        th = np.radians(np.linspace(max(colat - 3, 0.01), colat + 3, 61))
        pix = hp.ang2pix(hr, th, np.full_like(th, 0.3))
        smoothed = hp.alm2map(hp.almxfl(a, bl), hr, lmax=lmax)[pix]
        d = np.arccos(np.clip(v @ np.array(hp.pix2vec(hr, pix)), -1, 1))
        point = np.exp(-d ** 2 / (2 * sig ** 2)) * area
        print(f"   | {colat:g} deg | {np.abs(smoothed - point).max() / area:.1e} |")


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--nside", type=int, default=64)
    args = ap.parse_args()
    band_limited_sky(args.nside)
    one_pixel(2 * args.nside)


if __name__ == "__main__":
    main()
