#!/usr/bin/env python3
"""The TOD's accuracy against colatitude, pixels per FWHM and the sky's band limit (docs/validation.md, "L").

For each sky band limit and beam width: a random polarized sky given by its a_lm (T, E, B, with a red
spectrum C_l = 1 / (1 + (l / 30)^2)), its maps at NSIDE, and one ideal detector with a circular
Gaussian beam (rho_max = 2.5 FWHM). Samples at fixed colatitudes from both poles (16 longitudes each,
random psi) and 400 random ones over the sphere. The reference is the exact harmonic smoothing at each
sample: the truncated Gaussian's transfer functions (Legendre for T, d^l_22 for Q and U, since the
co-polar axis of Ludwig's third definition is parallel transport along each great circle from the
axis) applied to the a_lm and evaluated at the samples by ducc0's synthesis_general. Errors are
relative to the TOD's RMS: the worst per colatitude (from the nearer pole) and the RMS of the random
samples, for each backend present, with the engine's corrections (quadrature="corrected") and without
them (quadrature="plain").

With --beam-types, a second table: every kind of beam on a grid (an elliptical Gaussian; litebird_sim's
elliptical b_lm through Beamsor.from_blm; a GRASP .grd file of the same beam written by
tools/make_grasp_beam.py; a HEALPix beamsor file written by Beamsor.write_fits) at its default grid
step, against the same beam on a grid at FWHM / 60 on the float64 reference ("converged"), for each sky
band limit and backend: the interpolation's share of the error, apart from the quadrature's. The beams
have --beam-per-fwhm pixels across their minor FWHM (6 by default) and ellipticity 1.5.

Prints a table; with --out writes accuracy.md (the tables), accuracy.json and accuracy.png. With
--check, exits 1 unless every case with >= 6 pixels per FWHM, at every band limit up to 3 NSIDE - 1,
on the polar copy, is within 1e-4 at every colatitude and 2e-5 RMS, and every beam type at its default step
within 1e-4 of its converged TOD at every colatitude, for both band limits.

Run with the Python package built in build/ and the tests' environment (ducc0, matplotlib):
    PYTHONPATH=build/python build/python-venv/bin/python tools/accuracy_map.py [--nside 128] [--out DIR]
"""

import argparse
import json
import math
import os
import sys

import numpy as np

import pisco
from pisco import deg

COLATITUDES = [0.0, 0.3, 1.0, 3.0, 10.0, 30.0, 48.19, 90.0]
PER_COLATITUDE = 16
RANDOM = 400


def windows(fwhm, rho_max, lmax):
    """T and polarization transfer functions of a Gaussian truncated at rho_max, normalized by its cap integral."""
    s = fwhm / math.sqrt(8 * math.log(2.0))
    x, w = np.polynomial.legendre.leggauss(4000)
    rho = 0.5 * rho_max * (x + 1)
    f = 0.5 * rho_max * w * np.exp(-rho**2 / (2 * s * s)) * np.sin(rho)
    c = np.cos(rho)
    t = np.zeros(lmax + 1)
    p = np.zeros(lmax + 1)
    p0, p1 = np.ones_like(c), c.copy()
    t[0] = f.sum()
    t[1] = (f * c).sum()
    for l in range(1, lmax):
        p0, p1 = p1, ((2 * l + 1) * c * p1 - l * p0) / (l + 1)
        t[l + 1] = (f * p1).sum()
    d0, d1 = np.zeros_like(c), ((1 + c) / 2) ** 2  # d^1_22 = 0, d^2_22
    p[2] = (f * d1).sum()
    for l in range(2, lmax):
        d0, d1 = d1, ((2 * l + 1) * (l * (l + 1.0) * c - 4) * d1 - (l + 1) * (l * l - 4.0) * d0) / (l * ((l + 1.0) ** 2 - 4))
        p[l + 1] = (f * d1).sum()
    norm = f.sum()
    return t / norm, p / norm


def random_alm(lmax, seed):
    import healpy as hp

    rng = np.random.default_rng(seed)
    n = hp.Alm.getsize(lmax)
    l, m = hp.Alm.getlm(lmax)
    out = []
    for amp in (1.0, 0.3, 0.1):
        a = (rng.standard_normal(n) + 1j * rng.standard_normal(n)) / np.sqrt(2)
        a[m == 0] = a[m == 0].real * np.sqrt(2)
        a *= np.sqrt(amp / (1.0 + (l / 30.0) ** 2))
        a[l < (0 if amp == 1.0 else 2)] = 0
        out.append(a)
    out[0][0] = 0
    return np.array(out)


def pointing(seed):
    rng = np.random.default_rng(seed)
    theta, phi = [], []
    for c in COLATITUDES:
        for north in (True, False):
            for k in range(PER_COLATITUDE):
                theta.append(c * deg if north else math.pi - c * deg)
                phi.append(2 * math.pi * k / PER_COLATITUDE + (1e-5 if k == 0 else 0.1))
    theta += list(np.arccos(2 * rng.random(RANDOM) - 1))
    phi += list(2 * math.pi * rng.random(RANDOM))
    theta, phi = np.array(theta), np.array(phi)
    psi = 2 * math.pi * rng.random(theta.size) - math.pi
    return theta, phi, psi


def exact_tod(alm, lmax, wt, wp, theta, phi, psi):
    import ducc0
    import healpy as hp

    loc = np.stack([theta, phi % (2 * math.pi)], 1)
    t = hp.almxfl(alm[0], wt)
    eb = np.array([hp.almxfl(alm[1], wp), hp.almxfl(alm[2], wp)])
    i = ducc0.sht.synthesis_general(alm=t[None], spin=0, lmax=lmax, loc=loc, epsilon=1e-12, nthreads=0)[0]
    q, u = ducc0.sht.synthesis_general(alm=eb, spin=2, lmax=lmax, loc=loc, epsilon=1e-12, nthreads=0)
    return 0.5 * (i + q * np.cos(2 * psi) + u * np.sin(2 * psi))


def check_conventions(nside):
    """ducc0's spin-2 synthesis at pixel centres against healpy's alm2map (the maps the engine sums)."""
    import ducc0
    import healpy as hp

    lmax = 2 * nside
    alm = random_alm(lmax, 1)
    maps = hp.alm2map(alm, nside, lmax=lmax)
    th, ph = hp.pix2ang(nside, np.arange(12 * nside * nside))
    loc = np.stack([th, ph], 1)
    q, u = ducc0.sht.synthesis_general(alm=alm[1:], spin=2, lmax=lmax, loc=loc, epsilon=1e-12, nthreads=0)
    err = max(np.abs(q - maps[1]).max(), np.abs(u - maps[2]).max()) / np.abs(maps[1:]).max()
    if err > 1e-9:
        sys.exit(f"accuracy_map: ducc0's Q, U differ from healpy's by {err:.1e}: conventions differ")


def backends_present(asked):
    present = {b.name for b in pisco.devices() if b.available}
    return [b for b in asked if b in present]


def run(args):
    import healpy as hp

    nside = args.nside
    pixel = math.sqrt(math.pi / 3) / nside
    theta, phi, psi = pointing(3)
    fixed = len(COLATITUDES) * 2 * PER_COLATITUDE
    fp = pisco.FocalPlane()
    fp.add("d")
    rows = []
    for band in args.bands:
        lmax = min(int(round(band * nside)), 3 * nside - 1)
        alm = random_alm(lmax, 7)
        maps = hp.alm2map(alm, nside, lmax=lmax)
        sky = pisco.Sky.from_maps(np.ascontiguousarray(maps))
        for per_fwhm in args.per_fwhm:
            fwhm = per_fwhm * pixel
            rho_max = 2.5 * fwhm
            wt, wp = windows(fwhm, rho_max, lmax)
            ref = exact_tod(alm, lmax, wt, wp, theta, phi, psi)
            scale = np.sqrt(np.mean((ref - ref.mean()) ** 2))
            beam = pisco.Beamsor.gaussian(fwhm, rho_max=rho_max)
            for backend in args.backends:
                for poles in ("corrected", "plain"):
                    with pisco.Engine(sky, beam, fp, backend=backend, quadrature=poles) as engine:
                        d = engine.convolve(0, theta, phi, psi)
                    e = np.abs(d - ref) / scale
                    worst = e[:fixed].reshape(len(COLATITUDES), 2 * PER_COLATITUDE).max(1)
                    row = dict(band=band, lmax=lmax, per_fwhm=per_fwhm, fwhm_deg=fwhm / deg, backend=backend, poles=poles,
                               worst=[float(x) for x in worst], rms=float(np.sqrt(np.mean(e[fixed:] ** 2))))
                    rows.append(row)
                    print(f"band {lmax:4d} ({band:.2f} NSIDE)  {per_fwhm:4.1f} px/FWHM  {backend:6s} {poles:7s}  "
                          + " ".join(f"{x:7.1e}" for x in worst) + f"   rms {row['rms']:.1e}", flush=True)
    return rows


BEAM_TYPES = ["elliptical", "b_lm", "GRASP file", "beamsor file"]


def beam_of(kind, minor, rho_max, step, workdir, nside):
    """Beam `kind` with minor FWHM `minor` (ellipticity 1.5, major axis at 0.3 rad) at grid step `step`
    (0: its default)."""
    major = 1.5 * minor
    if kind == "elliptical":
        return pisco.Beamsor.elliptical_gaussian(major, minor, 0.3, rho_max=rho_max, grid_step=step)
    if kind == "b_lm":
        from litebird_sim.beam_synthesis import gauss_beam_to_alm

        lmax = int(12 / minor)  # the Gaussian's b_l down to 1e-12 and beyond
        blm = np.array(gauss_beam_to_alm(lmax=lmax, mmax=12, fwhm_rad=math.sqrt(major * minor), ellipticity=1.5,
                                         psi_ell_rad=0.3, psi_pol_rad=0.0, cross_polar_leakage=0.02).values)
        return pisco.Beamsor.from_blm(blm, rho_max=rho_max, grid_step=step, lmax=lmax, mmax=12)
    if kind == "GRASP file":
        path = os.path.join(workdir, "beam.grd")
        if not os.path.exists(path):
            sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
            from make_grasp_beam import write_grd

            half = rho_max / deg * 1.05
            n = int(math.ceil(2 * math.sin(half * deg) / (minor / 8))) + 1  # a file sampled at FWHM / 8
            write_grd(path, major / deg, minor / deg, half, n)
        return pisco.Beamsor.from_grasp(path, rho_max=rho_max, grid_step=step)
    if kind == "beamsor file":
        path = os.path.join(workdir, "beamsor.fits")
        if not os.path.exists(path):
            beam_of("elliptical", minor, rho_max, minor / 60, workdir, nside).write_fits(path, 8 * nside)
        return pisco.Beamsor.read_fits(path, rho_max=rho_max, grid_step=step)
    raise ValueError(kind)


def run_beam_types(args):
    """The interpolation's error per beam type at its default step (see the module's docstring)."""
    import tempfile

    import healpy as hp

    nside = args.nside
    pixel = math.sqrt(math.pi / 3) / nside
    minor = args.beam_per_fwhm * pixel
    rho_max = 2.5 * 1.5 * minor
    theta, phi, psi = pointing(5)
    fixed = len(COLATITUDES) * 2 * PER_COLATITUDE
    fp = pisco.FocalPlane()
    fp.add("d", zeta=0.4, epsilon=0.0)
    rows = []
    with tempfile.TemporaryDirectory() as workdir:
        for kind in BEAM_TYPES:
            converged = beam_of(kind, minor, rho_max, minor / 60, workdir, nside)
            default = beam_of(kind, minor, rho_max, 0.0, workdir, nside)
            for band in args.bands:
                lmax = min(int(round(band * nside)), 3 * nside - 1)
                sky = pisco.Sky.from_maps(np.ascontiguousarray(hp.alm2map(random_alm(lmax, 9), nside, lmax=lmax)))
                with pisco.Engine(sky, converged, fp, backend="cpu") as engine:
                    ref = engine.convolve(0, theta, phi, psi)
                scale = np.sqrt(np.mean((ref - ref.mean()) ** 2))
                for backend in args.backends:
                    with pisco.Engine(sky, default, fp, backend=backend) as engine:
                        d = engine.convolve(0, theta, phi, psi)
                    e = np.abs(d - ref) / scale
                    worst = e[:fixed].reshape(len(COLATITUDES), 2 * PER_COLATITUDE).max(1)
                    row = dict(beam=kind, step_arcmin=default.grid_step / deg * 60 if not default.is_radial else None,
                               minor_per_step=minor / default.grid_step, band=band, lmax=lmax, backend=backend,
                               worst=[float(x) for x in worst], rms=float(np.sqrt(np.mean(e[fixed:] ** 2))))
                    rows.append(row)
                    print(f"{kind:12s} step FWHM/{row['minor_per_step']:5.1f}  band {lmax:4d} ({band:.2f} NSIDE)  "
                          f"{backend:6s}  " + " ".join(f"{x:7.1e}" for x in worst) + f"   rms {row['rms']:.1e}", flush=True)
    return rows


def beam_table(rows, nside, per_fwhm):
    head = "| beam | default step | band limit | backend | " + " | ".join(f"{c:g} deg" for c in COLATITUDES) + " | RMS |"
    out = [f"NSIDE {nside}, beams of {per_fwhm:g} pixels across their minor FWHM (ellipticity 1.5): each beam at its "
           "default grid step against the same beam at FWHM / 60 (float64 reference); worst error per colatitude",
           f"from the nearer pole and RMS over {RANDOM} random samples, relative to the TOD's RMS.", "", head,
           "|" + "---|" * (len(COLATITUDES) + 5)]
    for r in rows:
        out.append(f"| {r['beam']} | FWHM / {r['minor_per_step']:.1f} | {r['lmax']} ({r['band']:g} NSIDE) | {r['backend']} | "
                   + " | ".join(f"{x:.1e}" for x in r["worst"]) + f" | {r['rms']:.1e} |")
    return "\n".join(out) + "\n"


def table(rows, nside):
    head = "| band limit | px/FWHM | backend | poles | " + " | ".join(f"{c:g} deg" for c in COLATITUDES) + " | RMS |"
    out = [f"NSIDE {nside}: worst error per colatitude from the nearer pole, and RMS over {RANDOM} random samples,",
           "relative to the TOD's RMS.", "", head, "|" + "---|" * (len(COLATITUDES) + 5)]
    for r in rows:
        out.append(f"| {r['lmax']} ({r['band']:g} NSIDE) | {r['per_fwhm']:g} | {r['backend']} | {r['poles']} | "
                   + " | ".join(f"{x:.1e}" for x in r["worst"]) + f" | {r['rms']:.1e} |")
    return "\n".join(out) + "\n"


def figure(rows, path, nside):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    bands = sorted({r["band"] for r in rows})
    backend = rows[0]["backend"]
    fig, axes = plt.subplots(1, len(bands), figsize=(5 * len(bands), 4), sharey=True, squeeze=False)
    x = [max(c, 0.1) for c in COLATITUDES]
    for ax, band in zip(axes[0], bands):
        for r in rows:
            if r["band"] != band or r["backend"] != backend:
                continue
            style = "-o" if r["poles"] == "corrected" else ":x"
            ax.loglog(x, np.maximum(r["worst"], 1e-9), style, label=f"{r['per_fwhm']:g} px/FWHM, {r['poles']}")
        ax.axhline(1e-4, color="k", lw=0.5)
        ax.set_title(f"band limit {rows[[r['band'] for r in rows].index(band)]['lmax']} ({band:g} NSIDE), {backend}")
        ax.set_xlabel("colatitude from the nearer pole [deg] (0 plotted at 0.1)")
    axes[0][0].set_ylabel("worst |error| / TOD RMS")
    axes[0][-1].legend(fontsize=6)
    fig.suptitle(f"PISCO-VK TOD against exact harmonic smoothing, NSIDE {nside}")
    fig.tight_layout()
    fig.savefig(path, dpi=110)


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--nside", type=int, default=128)
    ap.add_argument("--per-fwhm", type=float, nargs="+", default=[3, 4, 6, 10, 20])
    ap.add_argument("--bands", type=float, nargs="+", default=[1.5, 2.0, 3.0], help="sky band limits in units of NSIDE (capped at 3 NSIDE - 1)")
    ap.add_argument("--backends", nargs="+", default=["cpu", "simd", "vulkan", "cuda"], help="those present are run")
    ap.add_argument("--out", help="directory for accuracy.md, accuracy.json and accuracy.png")
    ap.add_argument("--check", action="store_true", help="exit 1 unless the bars hold (>= 6 px/FWHM, every band limit)")
    ap.add_argument("--beam-types", action="store_true", help="also every beam type at its default grid step")
    ap.add_argument("--beam-per-fwhm", type=float, default=6.0, help="pixels across the beam types' minor FWHM")
    args = ap.parse_args()
    args.backends = backends_present(args.backends)
    if not args.backends:
        sys.exit("accuracy_map: none of the backends asked for is present")
    check_conventions(min(args.nside, 64))
    rows = run(args)
    beam_rows = run_beam_types(args) if args.beam_types else []
    if args.out:
        os.makedirs(args.out, exist_ok=True)
        with open(os.path.join(args.out, "accuracy.json"), "w") as f:
            json.dump(dict(nside=args.nside, colatitudes_deg=COLATITUDES, rows=rows, beam_rows=beam_rows), f, indent=1)
        with open(os.path.join(args.out, "accuracy.md"), "w") as f:
            f.write(table(rows, args.nside))
            if beam_rows:
                f.write("\n" + beam_table(beam_rows, args.nside, args.beam_per_fwhm))
        figure(rows, os.path.join(args.out, "accuracy.png"), args.nside)
    if args.check:
        bad = [r for r in rows
               if r["poles"] == "corrected" and r["per_fwhm"] >= 6 and (max(r["worst"]) > 1e-4 or r["rms"] > 2e-5)]
        plain_pole = [r for r in rows if r["poles"] == "plain" and r["per_fwhm"] >= 6 and r["worst"][0] <= 1e-3]
        for r in bad:
            print(f"FAIL: band {r['lmax']}, {r['per_fwhm']:g} px/FWHM, {r['backend']}: worst {max(r['worst']):.1e}, rms {r['rms']:.1e}")
        for r in plain_pole:
            print(f"FAIL: the plain sum at the pole should miss by > 1e-3 (the test's power), got {r['worst'][0]:.1e}")
        bad_beams = [r for r in beam_rows if args.beam_per_fwhm >= 6 and max(r["worst"]) > 1e-4]
        for r in bad_beams:
            print(f"FAIL: {r['beam']} at its default step, band {r['lmax']}, {r['backend']}: worst {max(r['worst']):.1e}")
        if bad or plain_pole or bad_beams:
            sys.exit(1)
        print("accuracy_map: the bars hold (>= 6 px/FWHM, band limits to 3 NSIDE - 1: <= 1e-4 everywhere, <= 2e-5 RMS)")


if __name__ == "__main__":
    main()
