#!/usr/bin/env python3
"""Mask-corrected power spectra of PISCO-VK's binned maps (paper 7.1.4) through NaMaster.

Run it with the Python of the spectra environment (tools/spectra_env.py VENV makes it: NaMaster, healpy,
numpy, matplotlib from PyPI). From maps.fits (I, Q, U, RING, UNSEEN where unsolved) and hits.fits:

1. the survey footprint: pixels solved by the map-maker (its condition-number cut, `rcond_min`) with at
   least --hits-min samples;
2. a galactic mask: |b| >= --galactic-cut-deg (20), the maps being in equatorial coordinates
   (--coord C; G for maps already in galactic coordinates, where the cut applies directly; E for
   ecliptic);
3. their product apodized (NaMaster's C2 taper, --apodize-deg 5);
4. pseudo-C_l with the mask's mode coupling (NaMaster's MASTER), B-mode purification on the spin-2
   field (--no-purify to turn it off), bandpowers of --bin-width multipoles, the beam window
   (--beam-window FILE, columns l b_l, e.g. validate's beam_window.txt from the mean radial profile; or
   --fwhm-deg for a Gaussian) times the NSIDE pixel window divided out.

Writes OUT/spectra_masked.txt (effective l, D_l TT EE BB TE EB TB in the maps' units squared, and the
Knox error of each from the mask's f_sky) and OUT/mask.fits. Errors name the file or option and exit 2.

Usage: pisco_spectra.py --maps maps.fits --hits hits.fits --out DIR [options]
       pisco_spectra.py --report DIR/F   (every case of validate's case F: spectra and PNG figures)
"""

import argparse
import math
import os
import sys

UNSEEN = -1.6375e30
# Debian's healpy-data (a dependency of the project): the pixel windows, which healpy from PyPI would
# otherwise download.
HEALPY_DATA = "/usr/share/healpy/data"


class InputError(Exception):
    pass


def read_map(path, fields, what):
    import healpy as hp
    import numpy as np
    if not os.path.isfile(path):
        raise InputError(f"{path}: no such file ({what})")
    try:
        m = hp.read_map(path, field=fields, dtype=np.float64)
    except Exception as exc:  # healpy raises many kinds
        raise InputError(f"{path}: cannot read {what} as a HEALPix map ({exc})")
    return np.atleast_2d(m)


def galactic_latitude_deg(nside, coord):
    import healpy as hp
    import numpy as np
    theta, phi = hp.pix2ang(nside, np.arange(hp.nside2npix(nside)))
    if coord != "G":
        theta, phi = hp.Rotator(coord=[coord, "G"])(theta, phi)
    return 90.0 - np.degrees(theta)


def pixel_window(nside, lmax):
    """Temperature and polarization pixel windows of NSIDE from healpy-data (l = 0..lmax)."""
    import numpy as np
    from astropy.io import fits
    path = os.path.join(HEALPY_DATA, f"pixel_window_n{nside:04d}.fits")
    if not os.path.isfile(path):
        raise InputError(f"{path}: no such file (Debian's healpy-data holds the pixel windows)")
    with fits.open(path) as f:
        t = f[1].data
        pt, pp = np.asarray(t.field(0), dtype=float), np.asarray(t.field(1), dtype=float)
    if pt.size <= lmax:
        raise InputError(f"{path}: the pixel window stops at l = {pt.size - 1}; the spectra need l <= {lmax}")
    return pt[: lmax + 1], pp[: lmax + 1]


def read_beam_window(path, lmax):
    import numpy as np
    try:
        t = np.loadtxt(path, ndmin=2)
    except (OSError, ValueError) as exc:
        raise InputError(f"{path}: cannot read the beam window (columns l b_l): {exc}")
    if t.shape[1] < 2 or not np.all(np.isfinite(t)):
        raise InputError(f"{path}: expected finite columns l b_l")
    bl = np.zeros(lmax + 1)
    ls = t[:, 0].astype(int)
    keep = (ls >= 0) & (ls <= lmax)
    bl[ls[keep]] = t[keep, 1]
    if ls.max() < lmax:
        raise InputError(f"{path}: the beam window stops at l = {ls.max()}; the spectra need l <= {lmax}")
    return bl


def masked_spectra(maps_path, hits_path, out, beam_window=None, fwhm_deg=None, hits_min=1, galactic_cut=20.0,
                   coord="C", apodize=5.0, bin_width=10, purify=True, lmax=None):
    """Computes and writes the mask-corrected bandpowers; returns (ell, dict of D_b, dict of errors, fsky)."""
    import healpy as hp
    import numpy as np
    import pymaster as nmt
    iqu = read_map(maps_path, (0, 1, 2), "I, Q, U maps")
    hits = read_map(hits_path, 0, "hits")[0]
    nside = hp.npix2nside(iqu.shape[1])
    if hits.size != iqu.shape[1]:
        raise InputError(f"{hits_path}: {hits.size} pixels; {maps_path} has {iqu.shape[1]}")
    lmax = lmax or 3 * nside - 1
    solved = np.all(np.abs(iqu - UNSEEN) > 1e25, axis=0) & np.all(np.isfinite(iqu), axis=0)
    footprint = solved & (hits >= hits_min)
    mask = footprint.astype(float)
    if galactic_cut > 0:
        mask *= np.abs(galactic_latitude_deg(nside, coord)) >= galactic_cut
    if mask.sum() == 0:
        raise InputError(f"{maps_path}: no pixel left after the footprint and the galactic cut")
    if apodize > 0:
        mask = nmt.mask_apodization(mask, apodize, apotype="C2")
    maps = np.where(footprint, iqu, 0.0)
    if beam_window is not None:
        bl = read_beam_window(beam_window, lmax)
    elif fwhm_deg is not None:
        bl = hp.gauss_beam(math.radians(fwhm_deg), lmax=lmax)
    else:
        bl = np.ones(lmax + 1)
    pt, pp = pixel_window(nside, lmax)
    pp = np.where(np.arange(lmax + 1) < 2, 1.0, pp)
    f0 = nmt.NmtField(mask, [maps[0]], beam=bl * pt, lmax=lmax)
    f2 = nmt.NmtField(mask, [maps[1], maps[2]], beam=bl * pp, purify_b=purify, lmax=lmax)
    b = nmt.NmtBin.from_lmax_linear(lmax, bin_width)
    ell = b.get_effective_ells()
    c00 = nmt.compute_full_master(f0, f0, b)
    c02 = nmt.compute_full_master(f0, f2, b)
    c22 = nmt.compute_full_master(f2, f2, b)
    cl = {"TT": c00[0], "TE": c02[0], "TB": c02[1], "EE": c22[0], "EB": c22[1], "BB": c22[3]}
    fsky = float(np.mean(mask ** 2) ** 2 / np.mean(mask ** 4))
    to_dl = ell * (ell + 1) / (2 * np.pi)
    dl = {k: v * to_dl for k, v in cl.items()}
    # Knox: var C_b = 2 C_b^2 / ((2l+1) bin_width f_sky) for auto spectra (no noise: the sample variance).
    err = {k: np.sqrt(2.0 / ((2 * ell + 1) * bin_width * fsky)) * np.abs(dl[k]) for k in ("TT", "EE", "BB")}
    os.makedirs(out, exist_ok=True)
    order = ["TT", "EE", "BB", "TE", "EB", "TB"]
    table = np.column_stack([ell] + [dl[k] for k in order] + [err[k] for k in ("TT", "EE", "BB")])
    np.savetxt(os.path.join(out, "spectra_masked.txt"), table, fmt="%.8g",
               header=(f"NaMaster {getattr(nmt, '__version__', '')} mask-corrected D_l (maps' units^2): footprint "
                       f"(hits >= {hits_min}, solved), |b| >= {galactic_cut} deg ({coord}), C2 apodization "
                       f"{apodize} deg, f_sky {fsky:.4f}, B purification {'on' if purify else 'off'}, bins of "
                       f"{bin_width}, beam and NSIDE {nside} pixel windows divided out\n"
                       "l_eff " + " ".join(order) + " err_TT err_EE err_BB"))
    hp.write_map(os.path.join(out, "mask.fits"), mask, overwrite=True, dtype=np.float64)
    return ell, dl, err, fsky


def tensor_reference(lmax):
    import numpy as np
    path = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "assets", "spectra", "tensor_bb_r1.txt")
    t = np.loadtxt(path)
    t = t[t[:, 0] <= lmax]
    return t[:, 0], 0.1 * t[:, 1]


def report(case_dir, args):
    """NaMaster spectra of every case under validate's F directory, its figures and a report section."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np
    cases = sorted(d for d in os.listdir(case_dir) if os.path.isfile(os.path.join(case_dir, d, "maps.fits")))
    if not cases:
        raise InputError(f"{case_dir}: no case directory with maps.fits")
    lines = ["", "## Mask-corrected spectra (NaMaster)", "",
             f"Footprint and |b| >= {args.galactic_cut_deg} deg galactic cut, C2-apodized {args.apodize_deg} deg, "
             "B-mode purification, bins of 10, the beam window of the mean radial profile and the pixel window "
             "divided out (tools/pisco_spectra.py). For the polarized case the harmonic image of the input is "
             "not subtracted here: its BB is the observation's P -> B plus the estimator's floor.", "",
             "Bandpowers to l = 2 NSIDE; \"above r = 0.1 from l\" is the first bin of the run above the r = 0.1 "
             "tensor BB that reaches l = 2 NSIDE.", "",
             "| case | f_sky | BB peak (uK^2) | at l | above r = 0.1 from l | figure |", "|---|---|---|---|---|---|"]
    for case in cases:
        d = os.path.join(case_dir, case)
        bw = os.path.join(d, "beam_window.txt")
        ell, dl, err, fsky = masked_spectra(os.path.join(d, "maps.fits"), os.path.join(d, "hits.fits"), d,
                                            beam_window=bw if os.path.isfile(bw) else None,
                                            galactic_cut=args.galactic_cut_deg, coord=args.coord,
                                            apodize=args.apodize_deg, bin_width=10)
        rl, rbb = tensor_reference(int(ell.max()) + 10)
        ref = np.interp(ell, rl, rbb)
        sel = (ell >= 2) & (ell <= 2 * (ell.max() + 5) / 3)  # to l = 2 NSIDE, where the windows are reliable
        peak_i = int(np.argmax(np.where(sel, dl["BB"], -np.inf)))
        # Where the leakage crosses r = 0.1: the first bin of the run above the tensor BB that reaches
        # l = 2 NSIDE (a low-l bin above it, such as the polarized case's E -> B floor, is not a crossing).
        idx = np.nonzero(sel)[0]
        above = np.zeros(0, dtype=int)
        if idx.size and dl["BB"][idx[-1]] > ref[idx[-1]]:
            k = idx[-1]
            while k - 1 >= idx[0] and dl["BB"][k - 1] > ref[k - 1]:
                k -= 1
            above = np.array([k])
        fig, ax = plt.subplots(figsize=(7, 4.2))
        for k, c in (("EE", "tab:blue"), ("BB", "tab:red")):
            ax.plot(ell[sel], np.abs(dl[k][sel]), color=c, label=f"|{k}|")
        keep = rl <= ell[sel].max()
        ax.plot(rl[keep], rbb[keep], "k--", lw=1, label="r = 0.1 tensor BB")
        ax.set_yscale("log")
        ax.set_xlabel(r"$\ell$")
        ax.set_ylabel(r"$D_\ell$ [$\mu$K$^2$]")
        ax.set_title(f"F, {case}: NaMaster, f_sky {fsky:.2f}")
        ax.legend(fontsize=8)
        fig.tight_layout()
        png = os.path.join(case_dir, f"F_{case}.png")
        fig.savefig(png, dpi=100)
        plt.close(fig)
        lines.append(f"| {case} | {fsky:.3f} | {dl['BB'][peak_i]:.3g} | {ell[peak_i]:.1f} | "
                     f"{ell[above[0]]:.1f} |" if above.size else
                     f"| {case} | {fsky:.3f} | {dl['BB'][peak_i]:.3g} | {ell[peak_i]:.1f} | - |")
        lines[-1] += f" ![{case}](F_{case}.png) |"
        print(f"{case}: f_sky {fsky:.3f}, BB peak {dl['BB'][peak_i]:.3g} uK^2 at l = {ell[peak_i]:.1f}", flush=True)
    with open(os.path.join(case_dir, "report.md"), "a") as f:
        f.write("\n".join(lines) + "\n")


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--maps")
    p.add_argument("--hits")
    p.add_argument("--out")
    p.add_argument("--report", help="validate's F directory: every case's spectra, figures, report section")
    p.add_argument("--beam-window")
    p.add_argument("--fwhm-deg", type=float)
    p.add_argument("--hits-min", type=int, default=1)
    p.add_argument("--galactic-cut-deg", type=float, default=20.0)
    p.add_argument("--coord", choices=["C", "G", "E"], default="C")
    p.add_argument("--apodize-deg", type=float, default=5.0)
    p.add_argument("--bin-width", type=int, default=10)
    p.add_argument("--no-purify", action="store_true")
    p.add_argument("--lmax", type=int)
    a = p.parse_args(argv)
    try:
        for name in ("galactic_cut_deg", "apodize_deg"):
            v = getattr(a, name)
            if not (math.isfinite(v) and v >= 0):
                raise InputError(f"--{name.replace('_', '-')}: expected a finite angle >= 0, got {v}")
        if a.bin_width < 1:
            raise InputError(f"--bin-width: expected a positive number of multipoles, got {a.bin_width}")
        if a.report:
            report(a.report, a)
            return 0
        if not (a.maps and a.hits and a.out):
            raise InputError("--maps, --hits and --out are required (or --report DIR)")
        ell, dl, err, fsky = masked_spectra(a.maps, a.hits, a.out, a.beam_window, a.fwhm_deg, a.hits_min,
                                            a.galactic_cut_deg, a.coord, a.apodize_deg, a.bin_width,
                                            not a.no_purify, a.lmax)
        print(f"pisco_spectra: f_sky {fsky:.4f}, {ell.size} bins to l = {ell.max():.1f}: "
              f"{os.path.join(a.out, 'spectra_masked.txt')}")
    except InputError as exc:
        print(f"pisco_spectra: error: {exc}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
