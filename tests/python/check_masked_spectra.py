"""A masked Gaussian realization of known C_l through tools/pisco_spectra.py recovers them within cosmic
variance: bandpowers of TT, EE and BB (bins of 10, 30 <= l < 250) against the binned input, with the
Knox error of each bin for the mask's f_sky. Run in the spectra environment (run_masked_spectra.py)."""
import os
import sys

import healpy as hp
import numpy as np

here = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(here, "..", "..", "tools"))
import pisco_spectra  # noqa: E402

out = sys.argv[1]
os.makedirs(out, exist_ok=True)
nside, lmax, fwhm = 128, 383, 1.5
t = np.loadtxt("/usr/share/healpy/data/totcls.dat")
ls = t[:, 0].astype(int)
cl = np.zeros((4, lmax + 1))
keep = (ls >= 2) & (ls <= lmax)
for k in range(4):  # TT EE BB TE as D_l
    cl[k, ls[keep]] = t[keep, k + 1] * 2 * np.pi / (ls[keep] * (ls[keep] + 1))
np.random.seed(2024)
alms = hp.synalm([cl[0], cl[1], cl[2], cl[3]], lmax=lmax, new=True)
pt, pp = pisco_spectra.pixel_window(nside, lmax)
bl = hp.gauss_beam(np.radians(fwhm), lmax=lmax)
alms = [hp.almxfl(alms[0], bl * pt), hp.almxfl(alms[1], bl * pp), hp.almxfl(alms[2], bl * pp)]
maps = hp.alm2map(alms, nside, lmax=lmax)
# A ground survey's footprint (declinations -70 to +20 deg), UNSEEN outside it as the map-maker writes.
theta, _ = hp.pix2ang(nside, np.arange(hp.nside2npix(nside)))
dec = 90 - np.degrees(theta)
seen = (dec > -70) & (dec < 20)
maps[:, ~seen] = hp.UNSEEN
hits = np.where(seen, 100.0, 0.0)
hp.write_map(os.path.join(out, "maps.fits"), maps, overwrite=True, dtype=np.float64)
hp.write_map(os.path.join(out, "hits.fits"), hits, overwrite=True, dtype=np.float64)

ell, dl, err, fsky = pisco_spectra.masked_spectra(os.path.join(out, "maps.fits"), os.path.join(out, "hits.fits"), out,
                                                  fwhm_deg=fwhm, galactic_cut=20.0, coord="C", apodize=5.0,
                                                  bin_width=10)
import pymaster as nmt  # noqa: E402
b = nmt.NmtBin.from_lmax_linear(3 * nside - 1, 10)
# From l = 30: below it the steep low-l spectra against the bandpower windows of a 5 deg apodized cut
# sky differ from the plain bin average by more than the variance (up to 19 sigma in EE at l ~ 15).
sel = (ell >= 30) & (ell < 250)
lines, ok_all = [], True
total_in, total_n, chi2_all = 0, 0, 0.0
for k, name in ((0, "TT"), (1, "EE"), (2, "BB")):
    theory = b.bin_cell(cl[k][None, :])[0] * ell * (ell + 1) / (2 * np.pi)
    sigma = np.sqrt(2.0 / ((2 * ell + 1) * 10 * fsky)) * theory
    z = (dl[name] - theory)[sel] / sigma[sel]
    within = np.mean(np.abs(z) < 2)
    chi2 = float(np.sum(z ** 2))
    total_in += int(np.sum(np.abs(z) < 2))
    total_n += z.size
    chi2_all += chi2
    print(f"{name}: {z.size} bins, chi^2 {chi2:.1f} ({chi2 / z.size:.2f} per bin), within 2 sigma {100 * within:.0f}%, "
          f"max |z| {np.max(np.abs(z)):.2f}")
print(f"f_sky {fsky:.3f}; all: chi^2 {chi2_all:.1f} for {total_n} bins ({chi2_all / total_n:.2f} per bin), "
      f"{100 * total_in / total_n:.0f}% within 2 sigma")
# Bars: at least 85% of the bins within 2 sigma (a Gaussian gives 95%) and chi^2 per bin below 2 (its
# expectation is about 1; purification and apodization add a little variance beyond Knox's).
if total_in / total_n < 0.85 or chi2_all / total_n > 2.0:
    print("FAIL: the mask-corrected spectra do not recover the input within cosmic variance")
    sys.exit(1)
print("pass")
