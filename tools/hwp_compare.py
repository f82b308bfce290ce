#!/usr/bin/env python3
"""PISCO-VK through a half-wave plate against litebird_sim's MuellerConvolver (docs/validation.md, H3), and both timed.

Run it with a Python that has litebird_sim, ducc0, healpy, h5py and numpy, e.g. the python tests'
environment: build/python-venv/bin/python tools/hwp_compare.py [--bench]. The ctest
python.litebird_hwp (tests/python/run_litebird_hwp.py) runs the comparison.

The comparison
--------------
One band-limited sky (I, Q, U from random alm with C_l ~ 1/(l (l + 1)), 2 <= l <= lmax), one round
Gaussian beam, one plate Mueller matrix, one set of random pointings (theta, phi, psi) and plate
angles h, through

- litebird_sim: ``MuellerConvolver(slm=alm, blm=beam, mueller=M0, lmax, kmax=2)`` and
  ``signal(ptg=(theta, phi, psi), alpha=h)`` in float64; without a plate, ducc0's
  ``totalconvolve.Interpolator``, which is litebird_sim's own path when there is no plate;
- PISCO-VK: ``pisco-vk run`` with the sky written by healpy at NSIDE >= 256 (``[sky] file``), the
  pointing as a boresight file (``[scan] type = "file"``: quaternions from the angles and the plate
  angle per sample as ``hwp_angle``), one detector on the boresight at zeta = 0 with gain 2,
  ``[hwp] model = "ideal"`` or ``"mueller"`` with the 16 numbers and no rotation keys, at the aperture
  (default) or ``--placement detector``.

Plates: none, ideal (diag(1, 1, -1, -1)) and generic (the ideal plate plus the leakage of
tests/test_hwp.cpp's generic_plate(): all 16 entries non-zero). Figure: the relative RMS
difference rms(pisco - litebird_sim) / rms(litebird_sim). Measured (10,000 samples, NSIDE 256, lmax
256): 2.9e-5 (no plate), 2.5e-5 (ideal), 2.6e-5 (generic), on cpu and vulkan, at either placement;
7.8e-6 with ``--grid-step-arcmin 1.5`` (PISCO-VK's beam grid, FWHM / 20 by default) and 4.8e-6 with
``--nside 512`` too: the figure is PISCO-VK's sampling of the beam and of the sky. A third
evaluation, the harmonic reference below, pins litebird_sim's conventions independently of
PISCO-VK; the plate's angle in the other sense misses by 0.24, the generic matrix transposed by
8e-3.

Conventions (found by this tool: each line is checked by the reference comparison it prints)
----------------------------------------------------------------------------------------------
- Pointing: ducc0 and litebird_sim take (theta, phi, psi) with psi the angle of the beam's x axis
  (the detector's polarization axis) from the meridian theta^ towards phi^ (COSMO), and measure
  I + Q cos 2 psi + U sin 2 psi when the E and B coefficients of a healpy-layout beam are multiplied
  by -sqrt(2) (the ducc0 convention of tools/ducc0_compare.py). PISCO-VK's chi = psi + zeta is the
  same angle; its boresight quaternion for the same pointing is R_z(phi) R_y(theta) R_z(psi) (TOAST's
  ``qarray.from_iso_angles``, (x, y, z, w)): the tool checks that PISCO-VK reads the angles back.
- Plate angle: MuellerConvolver's ``alpha`` is PISCO-VK's theta = h - gamma, the plate's angle from
  the detector's polarization axis in the same sense as psi; here gamma = 0 (zeta = 0, no offset), so
  alpha = h. Its matrix at that angle is R(-alpha) M0 R(alpha), with PISCO-VK's R(a) (rows (1,0,0,0),
  (0,cos2a,sin2a,0), (0,-sin2a,cos2a,0), (0,0,0,1)).
- Mueller matrix: ``mueller`` is PISCO-VK's M0 entry for entry: rows the Stokes parameters leaving
  the plate towards the detector, columns those arriving from the sky, order I, Q, U, V, the fast
  axis along the detector's polarization axis at alpha = 0; litebird_sim 0.18.0's mueller_to_C
  conjugates its coherence-basis matrix to that effect.
- Beam normalization: the beam's T coefficients are sqrt((2l+1)/4pi) b_l with healpy's
  gauss_beam (b_0 = 1: unit integral); PISCO-VK's integral normalization divides by the beam's
  integral over the disc. PISCO-VK's ideal detector measures half of I + Q cos 2chi + U sin 2chi
  (D = s/2 (1, 1, 0, 0) in its frame), so the detector has gain s = 2.
- Windows: litebird_sim gives each row of the plate's matrix the window of the beam component that
  reads it: row I the beam's T window, rows Q and U its polarized window (healpy's polarized
  Gaussian window, exp(2 sigma^2) times the T window), whatever the spin of the sky component the
  entry brings in. PISCO-VK has one beam b(rho) in real space for every element (B = b times the
  identity): the sky's I and V reach every row through the T window of b, its Q and U through the
  spin-2 window of b (healpy's polarized window: measured, PISCO-VK's polarized TOD is 14x closer to
  it than to the T window). For the entries that mix temperature and polarization (and V into Q, U)
  the two models differ by 2 sigma^2 (2.5e-4 at FWHM 1.5 deg) times the entry: below the figure on
  an I, Q, U sky, and the whole of the V-only sky's 2.3e-4 (below). With such a beam
  the plate at the aperture and between the optics and the detector give the same TOD in PISCO-VK,
  and litebird_sim's element "in front of the detector" is both.
- The harmonic reference (harmonic_reference()): the sky smoothed by ducc0, turned into the
  detector's frame by R(psi), through R(-alpha) M0 R(alpha), the detector reading rows I and Q, with
  the windows by rows (litebird_sim's model) or by sky components (PISCO-VK's). litebird_sim matches
  the first to its interpolation accuracy (2.4e-10), entry by entry, except the V column (below);
  PISCO-VK matches the second at its figure.
- litebird_sim 0.18.0's V column: its effective beam for a V sky takes the beam's spin +2 and spin
  -2 parts shifted by m + 2 and m - 2, the opposite of its own T row (mueller_convolver.py, "V
  component"), so M_QV and M_UV act wrongly. On a V-only sky (``--v-sky``, part of the ctest) the
  tool shows it: litebird_sim misses the reference by 1.3 (relative RMS) while PISCO-VK agrees with
  its reference at 3.7e-5, and litebird_sim's own code with that row's shifts exchanged agrees with
  the reference to 2.4e-10 (and with PISCO-VK to 2.3e-4, the windows). The headline comparison
  uses an I, Q, U sky, where M's V column does not act; a detector that measures no V cannot see
  M's V row: 12 of the 16 entries are compared.

Timing (``--bench``)
--------------------
The paper's Table 1 workload (tools/ducc0_compare.py, docs/validation.md "G"): an lmax 383 sky,
every NSIDE 128 pixel centre at psi = 0, 45, 90 deg for a PSB pair (1,179,648 samples), FWHM 1.5 deg,
the plate turning at 2 Hz at 200 Hz (as ``pisco-vk bench --hwp``). litebird_sim builds a convolver
per detector (add_convolved_sky_to_one_detector), so each detector pays its set-up; both set-up and
interpolation are timed, float64 and float32 (litebird_sim's default), epsilon 1e-5, on
``--threads`` threads. ``pisco-vk bench --hwp none|ideal|generic -b cpu|vulkan --rho-max 5`` runs
in between, round after round (``--rounds``), so that the machine's drift touches both alike.
"""
import argparse
import inspect
import os
import re
import subprocess
import sys
import tempfile
import time

import h5py
import healpy as hp
import numpy as np

# All 16 entries perturbed, a 2% loss in M_II keeping the plate passive (docs/physics.md, "Physical
# bounds on Mueller matrices").
GENERIC_LEAK = np.array([[-0.02, 0.012, -0.008, 0.005],
                         [0.021, -0.03, 0.017, -0.011],
                         [-0.015, 0.009, 0.025, 0.04],
                         [0.007, -0.02, 0.033, 0.02]])
IDEAL = np.diag([1.0, 1.0, -1.0, -1.0])
PLATES = {"none": None, "ideal": IDEAL, "generic": IDEAL + GENERIC_LEAK}


# ---------------------------------------------------------------------------------------------
# Sky, beam, pointing


def random_alm(lmax, seed, scales):
    """alm (len(scales), nalm): C_l = scale * 2 pi 1000 / (l (l + 1)) for 2 <= l <= lmax."""
    l = np.arange(lmax + 1, dtype=float)
    cl = np.zeros(lmax + 1)
    cl[2:] = 2 * np.pi * 1000.0 / (l[2:] * (l[2:] + 1))
    rng = np.random.default_rng(seed)
    alm = np.zeros((len(scales), hp.Alm.getsize(lmax)), dtype=np.complex128)
    for comp, scale in enumerate(scales):
        if scale == 0:
            continue
        for m in range(lmax + 1):
            ls = np.arange(m, lmax + 1)
            idx = hp.Alm.getidx(lmax, ls, m)
            sd = np.sqrt(cl[ls] * scale)
            if m == 0:
                alm[comp, idx] = sd * rng.standard_normal(len(ls))
            else:
                alm[comp, idx] = sd * (rng.standard_normal(len(ls)) + 1j * rng.standard_normal(len(ls))) / np.sqrt(2)
    return alm


def gaussian_blm(lmax, fwhm, ncomp=3):
    """A polarized Gaussian beam in healpy's layout (mmax 2), E and B times -sqrt(2) (ducc0's convention)."""
    bl = hp.gauss_beam(fwhm, lmax=lmax, pol=True)  # columns T, E, B, TE
    blm = np.zeros((ncomp, hp.Alm.getsize(lmax, 2)), dtype=np.complex128)
    l = np.arange(lmax + 1)
    blm[0, hp.Alm.getidx(lmax, l, 0)] = np.sqrt((2 * l + 1) / (4 * np.pi)) * bl[:, 0]
    lp = l[2:]
    e = np.sqrt((2 * lp + 1) / (32 * np.pi)) * bl[2:, 1]
    blm[1, hp.Alm.getidx(lmax, lp, 2)] = -np.sqrt(2) * e
    blm[2, hp.Alm.getidx(lmax, lp, 2)] = -np.sqrt(2) * 1j * e
    return blm


def quat_mult(p, q):
    """Hamilton product of (x, y, z, w) quaternions, row by row."""
    px, py, pz, pw = p.T
    qx, qy, qz, qw = q.T
    return np.stack([pw * qx + px * qw + py * qz - pz * qy,
                     pw * qy - px * qz + py * qw + pz * qx,
                     pw * qz + px * qy - py * qx + pz * qw,
                     pw * qw - px * qx - py * qy - pz * qz], axis=1)


def from_iso_angles(theta, phi, psi):
    """R_z(phi) R_y(theta) R_z(psi) as (x, y, z, w): TOAST's qarray.from_iso_angles, PISCO-VK's frame."""
    zero = np.zeros_like(theta)

    def about(axis, angle):
        s, c = np.sin(angle / 2), np.cos(angle / 2)
        parts = [zero, zero, zero]
        parts[axis] = s
        return np.stack(parts + [c], axis=1)

    return quat_mult(quat_mult(about(2, phi), about(1, theta)), about(2, psi))


def random_pointing(n, seed):
    rng = np.random.default_rng(seed)
    theta = np.arccos(rng.uniform(-1, 1, n))
    phi = rng.uniform(0, 2 * np.pi, n)
    psi = rng.uniform(-np.pi, np.pi, n)
    h = rng.uniform(0, 2 * np.pi, n)
    return np.stack([theta, phi, psi], axis=1), h


def stokes_rotation(a):
    """R(a) per sample, (n, 4, 4): rows (1,0,0,0), (0,c,s,0), (0,-s,c,0), (0,0,0,1), c = cos 2a."""
    c, s = np.cos(2 * a), np.sin(2 * a)
    r = np.zeros((len(a), 4, 4))
    r[:, 0, 0] = r[:, 3, 3] = 1
    r[:, 1, 1] = r[:, 2, 2] = c
    r[:, 1, 2] = s
    r[:, 2, 1] = -s
    return r


# ---------------------------------------------------------------------------------------------
# The three evaluations


def litebird(slm, blm, lmax, plate, ptg, alpha, epsilon, nthreads, single=False, convolver=None):
    """litebird_sim's TOD: MuellerConvolver with a plate, ducc0's Interpolator without (its own path)."""
    import ducc0

    if plate is None:
        kind = ducc0.totalconvolve.Interpolator_f if single else ducc0.totalconvolve.Interpolator
        ctype, ftype = (np.complex64, np.float32) if single else (np.complex128, np.float64)
        inter = kind(sky=slm.astype(ctype), beam=blm.astype(ctype), separate=False, lmax=lmax, kmax=2,
                     epsilon=epsilon, nthreads=nthreads)
        return inter.interpol(ptg.astype(ftype))[0].astype(np.float64)
    if convolver is None:
        from litebird_sim import MuellerConvolver as convolver
    conv = convolver(slm=slm, blm=blm, mueller=plate, lmax=lmax, kmax=2, single_precision=single,
                     epsilon=epsilon, nthreads=nthreads)
    return np.asarray(conv.signal(ptg=ptg, alpha=alpha, strict_typing=False), dtype=np.float64)


def litebird_v_fixed():
    """litebird_sim's MuellerConvolver with its V row's m shifts exchanged (as its T row), or None."""
    import litebird_sim.mueller_convolver as module

    source = inspect.getsource(module)
    wrong = ("get_d(1, i_m_plus_2)\n                                  +(C[2, 3]*e2ia)  * get_d(2, i_m_minus_2))")
    right = ("get_d(1, i_m_minus_2)\n                                  +(C[2, 3]*e2ia)  * get_d(2, i_m_plus_2))")
    if wrong not in source:
        return None
    namespace = {}
    exec(compile(source.replace(wrong, right), module.__file__ + " (V row shifts exchanged)", "exec"), namespace)
    return namespace["MuellerConvolver"]


def harmonic_reference(slm, lmax, fwhm, plate, ptg, alpha, nthreads, windows):
    """The TOD of a round Gaussian beam from the sky smoothed by ducc0, turned into the detector's
    frame by R(psi), through R(-alpha) M0 R(alpha), the detector reading rows I and Q.

    windows = "rows" (litebird_sim's model): row I with the beam's T window, row Q with its
    polarized window, whatever sky component the entry brings in. windows = "columns" (one beam
    b(rho) in real space for every element, PISCO-VK's model): the sky's I and V with the T window,
    its Q and U with the polarized window (the spin-2 window of the same beam), whatever row. The
    polarized window is exp(2 sigma^2) times the T window (healpy's gauss_beam).
    """
    import ducc0

    bl = hp.gauss_beam(fwhm, lmax=lmax)
    l = np.arange(lmax + 1)
    beam_t = np.zeros((1, hp.Alm.getsize(lmax, 2)), dtype=np.complex128)
    beam_t[0, hp.Alm.getidx(lmax, l, 0)] = np.sqrt((2 * l + 1) / (4 * np.pi)) * bl
    beam_p = np.zeros((3, hp.Alm.getsize(lmax, 2)), dtype=np.complex128)
    e = np.sqrt((2 * l[2:] + 1) / (32 * np.pi)) * bl[2:]
    beam_p[1, hp.Alm.getidx(lmax, l[2:], 2)] = -np.sqrt(2) * e
    beam_p[2, hp.Alm.getidx(lmax, l[2:], 2)] = -np.sqrt(2) * 1j * e
    n = len(ptg)
    s = np.zeros((n, 4))  # I, Q, U, V in the detector's frame (psi), T window

    def interp(sky, beam, p):
        return ducc0.totalconvolve.Interpolator(sky, beam, False, lmax, 2, epsilon=1e-11,
                                                nthreads=nthreads).interpol(p)[0]

    s[:, 0] = interp(slm[0:1], beam_t, ptg)
    if np.any(slm[1:3]):
        sky_p = np.zeros((3, slm.shape[1]), dtype=np.complex128)
        sky_p[1:3] = slm[1:3]
        s[:, 1] = interp(sky_p, beam_p, ptg)
        turned = ptg.copy()
        turned[:, 2] += np.pi / 4
        s[:, 2] = interp(sky_p, beam_p, turned)  # at psi + pi/4: -Q sin 2psi + U cos 2psi
    if slm.shape[0] > 3 and np.any(slm[3]):
        s[:, 3] = interp(slm[3:4], beam_t, ptg)
    sigma = fwhm / np.sqrt(8 * np.log(2))
    polarized = np.exp(2 * sigma ** 2)
    if windows == "columns":
        s[:, 1:3] *= polarized
    if plate is None:
        out = s
    else:
        mt = np.einsum("nij,jk,nkl->nil", stokes_rotation(-alpha), plate, stokes_rotation(alpha))
        out = np.einsum("nij,nj->ni", mt, s)
    return out[:, 0] + (polarized if windows == "rows" else 1.0) * out[:, 1]


def pisco_run(pisco, work, tag, sky_fits, pointing_h5, plate, args):
    """`pisco-vk run` on the boresight file; returns (TOD, theta, phi, psi)."""
    out = os.path.join(work, f"out_{tag}")
    config = os.path.join(work, f"{tag}.toml")
    hwp = ""
    if plate is not None:
        numbers = ", ".join(repr(float(x)) for x in np.asarray(plate).ravel())
        hwp = f'[hwp]\nmodel = "mueller"\nmueller = [{numbers}]\nplacement = "{args.placement}"\n'
    with open(config, "w") as f:
        f.write(f"""# tools/hwp_compare.py: {tag}
[sky]
file = "{sky_fits}"

[beams.main]
type = "gaussian"
fwhm_deg = {args.fwhm_deg!r}
rho_max_deg = {args.rho_max_deg!r}
grid_step_arcmin = {args.grid_step_arcmin!r}

[[focal_plane.detectors]]
name = "d"
gain = 2.0
beam = "main"

[scan]
type = "file"
file = "{pointing_h5}"

{hwp}
[engine]
backend = "{args.backend}"

[output]
dir = "{out}"
tod = true
tod_pointing = true
maps = false
spectra = false
plots = false
""")
    ran = subprocess.run([pisco, "run", config, "-q", "--no-plots"], capture_output=True, text=True)
    if ran.returncode != 0:
        raise SystemExit(f"pisco-vk run {config} failed (status {ran.returncode}):\n{ran.stdout}{ran.stderr}")
    with h5py.File(os.path.join(out, "tod.h5"), "r") as f:
        g = f["d"]
        return tuple(np.asarray(g[k], dtype=np.float64) for k in ("signal", "theta", "phi", "psi"))


def rel_rms(a, b):
    return float(np.sqrt(np.mean((a - b) ** 2) / np.mean(b ** 2)))


def compare(args):
    """The H3 comparison; returns True when every figure is within its bar."""
    import litebird_sim

    nthreads = args.threads
    lmax = args.lmax if args.lmax else 2 * args.nside
    if lmax > 2 * args.nside:
        raise SystemExit(f"--lmax {lmax} exceeds 2 NSIDE = {2 * args.nside}")
    fwhm = np.radians(args.fwhm_deg)
    ptg, h = random_pointing(args.samples, seed=7)
    alpha = h  # gamma = 0: the detector on the boresight at zeta = 0
    print(f"litebird_sim {litebird_sim.__version__} (MuellerConvolver), pisco-vk -b {args.backend}: "
          f"NSIDE {args.nside} sky, lmax {lmax}, FWHM {args.fwhm_deg} deg, rho_max {args.rho_max_deg} deg, "
          f"{args.samples} random pointings and plate angles, plate at the {args.placement}", flush=True)
    blm = gaussian_blm(lmax, fwhm)
    blm4 = gaussian_blm(lmax, fwhm, ncomp=4)
    skies = {"IQU": random_alm(lmax, 3, (1.0, 0.05, 0.005))}
    if args.v_sky:
        skies["V"] = random_alm(lmax, 4, (0.0, 0.0, 0.0, 0.05))
    ok = True
    with tempfile.TemporaryDirectory(prefix="pisco-hwp-compare-") as work:
        work = args.workdir or work
        os.makedirs(work, exist_ok=True)
        pointing_h5 = os.path.join(work, "pointing.h5")
        with h5py.File(pointing_h5, "w") as f:
            f.create_dataset("boresight", data=from_iso_angles(ptg[:, 0], ptg[:, 1], ptg[:, 2]))
            f.create_dataset("hwp_angle", data=h)
        worst_pointing = 0.0
        for sky_name, slm in skies.items():
            sky_fits = os.path.join(work, f"sky_{sky_name}.fits")
            maps = hp.alm2map(slm[:3], args.nside, lmax=lmax, pol=True)
            columns = ["I_STOKES", "Q_STOKES", "U_STOKES"]
            if slm.shape[0] > 3:
                maps = np.vstack([maps, hp.alm2map(slm[3], args.nside, lmax=lmax)[None]])
                columns.append("V_STOKES")
            hp.write_map(sky_fits, maps, column_names=columns, column_units="uK_CMB", dtype=np.float64,
                         overwrite=True)
            plates = PLATES.items() if sky_name == "IQU" else [("generic", PLATES["generic"])]
            for name, plate in plates:
                t0 = time.perf_counter()
                mine, theta, phi, psi = pisco_run(args.pisco, work, f"{sky_name}_{name}", sky_fits, pointing_h5,
                                                  plate, args)
                t_pisco = time.perf_counter() - t0
                d_psi = np.remainder(psi - ptg[:, 2] + np.pi, 2 * np.pi) - np.pi
                worst_pointing = max(worst_pointing, float(np.max(np.abs(theta - ptg[:, 0]))),
                                     float(np.max(np.abs(np.remainder(phi - ptg[:, 1] + np.pi, 2 * np.pi) - np.pi))),
                                     float(np.max(np.abs(d_psi))))
                t0 = time.perf_counter()
                beam = blm if slm.shape[0] == 3 else blm4
                theirs = litebird(slm, beam, lmax, plate, ptg, alpha, args.epsilon, nthreads)
                t_lbs = time.perf_counter() - t0
                ref_rows = harmonic_reference(slm, lmax, fwhm, plate, ptg, alpha, nthreads, "rows")
                ref_columns = harmonic_reference(slm, lmax, fwhm, plate, ptg, alpha, nthreads, "columns")
                vs_lbs = rel_rms(mine, theirs)
                vs_ref = rel_rms(mine, ref_columns)
                lbs_ref = rel_rms(theirs, ref_rows)
                label = f"{sky_name} sky, {name} plate"
                if sky_name == "IQU":
                    good = vs_lbs <= args.tolerance and vs_ref <= args.tolerance and lbs_ref <= 1e-6
                    print(f"{label:>24}: pisco vs litebird_sim {vs_lbs:.2e}, pisco vs harmonic reference "
                          f"{vs_ref:.2e}, litebird_sim vs reference {lbs_ref:.1e} (pisco {t_pisco:.1f} s, "
                          f"litebird_sim {t_lbs:.1f} s): {'ok' if good else 'FAILED'}", flush=True)
                    if plate is not None and not args.no_wrong:
                        # What a convention error would look like: the plate's angle in the other sense,
                        # and the Mueller matrix transposed.
                        wrong_sense = rel_rms(mine, litebird(slm, blm, lmax, plate, ptg, -alpha, args.epsilon,
                                                             nthreads))
                        line = f"{'':>24}  pisco vs litebird_sim with alpha = -theta: {wrong_sense:.2e}"
                        if name == "generic":
                            transposed = rel_rms(mine, litebird(slm, blm, lmax, plate.T, ptg, alpha, args.epsilon,
                                                                nthreads))
                            line += f", with M0 transposed: {transposed:.2e}"
                            good = good and transposed > max(args.tolerance, 10 * vs_lbs)
                        print(line, flush=True)
                        good = good and wrong_sense > 0.1
                else:
                    fixed = litebird_v_fixed()
                    fixed_ref = None
                    if fixed is not None:
                        theirs_fixed = litebird(slm, beam, lmax, plate, ptg, alpha, args.epsilon, nthreads,
                                                convolver=fixed)
                        fixed_ref = rel_rms(theirs_fixed, ref_rows)
                        fixed_pisco = rel_rms(mine, theirs_fixed)
                    good = vs_ref <= args.tolerance
                    print(f"{label:>24}: pisco vs harmonic reference {vs_ref:.2e}: {'ok' if good else 'FAILED'}; "
                          f"litebird_sim vs reference {lbs_ref:.2e}"
                          + (f"; litebird_sim with its V row's m shifts exchanged vs reference {fixed_ref:.1e}, "
                             f"vs pisco {fixed_pisco:.2e} (the windows)" if fixed_ref is not None else "")
                          + f" (pisco vs litebird_sim {vs_lbs:.2e})", flush=True)
                ok = ok and good
        pointing_ok = worst_pointing < 1e-10
        print(f"pointing: pisco-vk's theta, phi, psi from the boresight quaternions R_z(phi) R_y(theta) R_z(psi) "
              f"within {worst_pointing:.1e} rad of the angles given to litebird_sim: "
              f"{'ok' if pointing_ok else 'FAILED'}")
        ok = ok and pointing_ok
    print(f"H3: {'passed' if ok else 'FAILED'} (bar {args.tolerance:g} relative RMS)")
    return ok


# ---------------------------------------------------------------------------------------------
# Timing


def table1(nside=128):
    theta, phi = hp.pix2ang(nside, np.arange(12 * nside * nside))
    psi = np.radians([0.0, 45.0, 90.0])
    ptg = np.concatenate([np.stack([theta, phi, np.full_like(theta, p)], axis=1) for p in psi])
    h = 2 * np.pi * 2.0 * np.arange(len(ptg)) / 200.0  # 2 Hz at 200 Hz, as pisco-vk bench --hwp
    return ptg, np.remainder(h, 2 * np.pi)


def bench_litebird(plate, single, args, sky, blm, ptg, h):
    """One Table 1 run: a convolver per detector of the pair; returns (set-up s, interpolation s)."""
    import ducc0
    from litebird_sim import MuellerConvolver

    setup = interp = 0.0
    ctype, ftype = (np.complex64, np.float32) if single else (np.complex128, np.float64)
    for zeta in (0.0, -np.pi / 2):
        p = ptg.copy()
        p[:, 2] = np.mod(p[:, 2] + zeta + 2 * np.pi, 4 * np.pi) - 2 * np.pi
        p = p.astype(ftype)
        t0 = time.perf_counter()
        if plate is None:
            conv = (ducc0.totalconvolve.Interpolator_f if single else ducc0.totalconvolve.Interpolator)(
                sky=sky.astype(ctype), beam=blm.astype(ctype), separate=False, lmax=args.bench_lmax, kmax=2,
                epsilon=args.bench_epsilon, nthreads=args.threads)
        else:
            conv = MuellerConvolver(slm=sky, blm=blm, mueller=plate, lmax=args.bench_lmax, kmax=2,
                                    single_precision=single, epsilon=args.bench_epsilon, nthreads=args.threads)
        t1 = time.perf_counter()
        if plate is None:
            tod = conv.interpol(p)[0]
        else:
            tod = conv.signal(ptg=p, alpha=(h - zeta).astype(ftype), strict_typing=False)
        t2 = time.perf_counter()
        assert np.all(np.isfinite(tod))
        setup += t1 - t0
        interp += t2 - t1
        del conv
    return setup, interp


def bench_pisco(args, plate, backend):
    cmd = [args.pisco, "bench", "-b", backend, "--rho-max", "5", "--hwp", plate]
    out = subprocess.run(cmd, capture_output=True, text=True)
    if out.returncode != 0:
        raise SystemExit(f"{' '.join(cmd)} failed ({out.returncode}):\n{out.stdout}{out.stderr}")
    for line in out.stdout.splitlines():
        m = re.match(r"\s*5\.0\s+([\d.]+)\s+([\d.]+)\s+([\d.]+)\s+([\d.e+-]+)", line)
        if m:
            return float(m.group(2)), float(m.group(3)), " ".join(cmd)
    raise SystemExit(f"cannot read {' '.join(cmd)}'s output:\n{out.stdout}")


def bench(args):
    import litebird_sim

    sky = random_alm(args.bench_lmax, 1, (1.0, 0.05, 0.005))
    blm = gaussian_blm(args.bench_lmax, np.radians(1.5))
    ptg, h = table1()
    n = 2 * len(ptg)
    print(f"Table 1 workload: {n} samples (2 detectors); litebird_sim {litebird_sim.__version__}, lmax "
          f"{args.bench_lmax}, kmax 2, epsilon {args.bench_epsilon:g}, {args.threads} threads; "
          f"pisco-vk bench --rho-max 5", flush=True)
    rows = {}
    for r in range(args.rounds):
        for plate in ("none", "ideal", "generic"):
            for backend in args.bench_backends:
                setup, conv, cmd = bench_pisco(args, plate, backend)
                rows.setdefault(("pisco-vk " + backend, plate), []).append((setup, conv))
                print(f"round {r + 1}: {cmd}: set-up {setup:.2f} s, convolution {conv:.2f} s, "
                      f"{n / conv:.3e} samples/s", flush=True)
            for single in (False, True):
                setup, interp = bench_litebird(PLATES[plate], single, args, sky, blm, ptg, h)
                key = ("litebird_sim " + ("float32" if single else "float64"), plate)
                rows.setdefault(key, []).append((setup, interp))
                print(f"round {r + 1}: litebird_sim {'ducc0 Interpolator' if plate == 'none' else 'MuellerConvolver'} "
                      f"{key[0].split()[1]}, {plate} plate: set-up {setup:.2f} s, interpolation {interp:.2f} s, "
                      f"{n / interp:.3e} samples/s ({n / (setup + interp):.3e} with set-up)", flush=True)
    print(f"\n{'code':<22}{'plate':<9}{'set-up s':>16}{'TOD s':>16}{'samples/s':>22}{'with set-up':>22}"
          f"{'time vs no plate (TOD, with set-up)':>38}")
    for (code, plate), runs in rows.items():
        base = rows[(code, "none")]
        tod_ratio = np.mean([c for _, c in runs]) / np.mean([c for _, c in base])
        all_ratio = np.mean([s + c for s, c in runs]) / np.mean([s + c for s, c in base])
        print(f"{code:<22}{plate:<9}{' / '.join(f'{s:.2f}' for s, _ in runs):>16}"
              f"{' / '.join(f'{c:.2f}' for _, c in runs):>16}"
              f"{' / '.join(f'{n / c:.2e}' for _, c in runs):>22}"
              f"{' / '.join(f'{n / (s + c):.2e}' for s, c in runs):>22}"
              f"{tod_ratio:>26.2f}x, {all_ratio:.2f}x")


def main():
    here = os.path.dirname(os.path.abspath(__file__))
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--pisco", default=os.path.join(here, "..", "build", "tools", "pisco-vk"),
                    help="the pisco-vk executable (default: build/tools/pisco-vk)")
    ap.add_argument("-b", "--backend", default="cpu", help="pisco-vk backend for the comparison (cpu)")
    ap.add_argument("--nside", type=int, default=256, help="NSIDE of PISCO-VK's sky map (256)")
    ap.add_argument("--lmax", type=int, default=256, help="lmax of sky and beam (256; at most 2 NSIDE)")
    ap.add_argument("--fwhm-deg", type=float, default=1.5, help="Gaussian beam FWHM (1.5 deg)")
    ap.add_argument("--rho-max-deg", type=float, default=5.0, help="PISCO-VK's disc radius (5 deg)")
    ap.add_argument("--grid-step-arcmin", type=float, default=0.0,
                    help="PISCO-VK's beam grid step (0: its default, FWHM / 20)")
    ap.add_argument("--samples", type=int, default=10000, help="random pointings (10000)")
    ap.add_argument("--placement", choices=["aperture", "detector"], default="aperture",
                    help="PISCO-VK's plate placement (aperture)")
    ap.add_argument("--epsilon", type=float, default=1e-9, help="litebird_sim's accuracy for the comparison")
    ap.add_argument("--tolerance", type=float, default=1e-3, help="bar on the relative RMS differences (1e-3)")
    ap.add_argument("--v-sky", action="store_true", help="also a V-only sky through the generic plate")
    ap.add_argument("--no-wrong", action="store_true", help="skip the convention-error lines")
    ap.add_argument("--no-check", action="store_true", help="skip the comparison")
    ap.add_argument("--workdir", help="keep the files here")
    ap.add_argument("--threads", type=int, default=os.cpu_count(), help="litebird_sim / ducc0 threads (all)")
    ap.add_argument("--bench", action="store_true", help="time the Table 1 workload through both")
    ap.add_argument("--rounds", type=int, default=2, help="bench rounds, alternated (2)")
    ap.add_argument("--bench-backends", nargs="+", default=["cpu", "vulkan"], help="pisco-vk backends (cpu vulkan)")
    ap.add_argument("--bench-lmax", type=int, default=383, help="litebird_sim's lmax for the bench (383)")
    ap.add_argument("--bench-epsilon", type=float, default=1e-5, help="litebird_sim's epsilon for the bench")
    args = ap.parse_args()
    args.pisco = os.path.abspath(args.pisco)
    ok = True
    if not args.no_check:
        ok = compare(args)
    if args.bench:
        bench(args)
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
