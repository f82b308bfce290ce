#!/usr/bin/env python3
"""The Table 1 workload (docs/validation.md, "G") through ducc0's harmonic total convolution, beside pisco-vk bench.

Workload: a full-sky NSIDE 128 input, every NSIDE 128 pixel centre at psi = 0, 45, 90 deg for a PSB pair
(2 detectors, zeta = 0 and -90 deg): 1,179,648 samples, a Gaussian beam of FWHM 1.5 deg.
ducc0.totalconvolve.Interpolator runs on all CPU cores; its set-up (building the data cube) and its
interpolation are timed apart. Then `pisco-vk bench -b BACKEND --rho-max ...` runs, and the samples/s of
both are printed side by side.

Also checks the two codes against each other on one sky: pisco's cpu TOD (from `pisco-vk run`) for a
pixel-centre scan at NSIDE 16 against ducc0's, on a band-limited sky synthesized from alm that ducc0
receives directly. They differ by pisco's pixel-space quadrature (the sky sampled at NSIDE 128 pixel
centres, the disc cut at rho_max = 5 deg); the relative RMS difference is printed.

Convention: ducc0 gives d = I + Q cos 2psi + U sin 2psi when the E and B beam
coefficients of healpy's blm layout are multiplied by -sqrt(2); the beam is built from healpy's
gauss_beam (healpy's blm_gauss omits the polarization factor). pisco's ideal detector measures half of
that (D = s/2 [1, cos 2chi, sin 2chi, 0]; docs/physics.md, "The measurement equation").

The script runs itself inside its own virtual environment (default ~/.cache/pisco/ducc0-venv), created
with python3 -m venv and filled with pip install ducc0 numpy healpy h5py where they are missing.
"""
import argparse
import os
import re
import subprocess
import sys
import tempfile
import time

REQUIREMENTS = ["ducc0", "numpy", "healpy", "h5py"]
TABLE1_NSIDE = 128
FWHM_DEG = 1.5


def ensure_venv(venv):
    """Re-executes this script under the venv's python, creating the venv first if needed."""
    if os.path.realpath(sys.prefix) == os.path.realpath(venv):
        return
    python = os.path.join(venv, "bin", "python")
    if not os.path.exists(python):
        print(f"creating the virtual environment {venv}", flush=True)
        subprocess.run([sys.executable, "-m", "venv", venv], check=True)
    missing = subprocess.run([python, "-c", "import ducc0, numpy, healpy, h5py"], capture_output=True).returncode
    if missing:
        print(f"installing {' '.join(REQUIREMENTS)} into {venv}", flush=True)
        subprocess.run([python, "-m", "pip", "install", "--quiet"] + REQUIREMENTS, check=True)
    os.execv(python, [python] + sys.argv)


def gaussian_blm(lmax, fwhm):
    """Polarized Gaussian beam in healpy's blm layout (mmax = 2), scaled for ducc0's convention."""
    import healpy as hp
    import numpy as np

    bl = hp.gauss_beam(fwhm, lmax=lmax, pol=True)  # columns T, E, B, TE
    blm = np.zeros((3, hp.Alm.getsize(lmax, 2)), dtype=np.complex128)
    l = np.arange(lmax + 1)
    blm[0, hp.Alm.getidx(lmax, l, 0)] = np.sqrt((2 * l + 1) / (4 * np.pi)) * bl[:, 0]
    lp = l[2:]
    e = np.sqrt((2 * lp + 1) / (32 * np.pi)) * bl[2:, 1]
    blm[1, hp.Alm.getidx(lmax, lp, 2)] = -np.sqrt(2) * e
    blm[2, hp.Alm.getidx(lmax, lp, 2)] = -np.sqrt(2) * 1j * e
    return blm


def random_sky_alm(lmax, seed):
    """A smooth, CMB-like polarized sky: C_l ~ 1/(l(l+1)) in T, 1/20 of it in E, 1/200 in B (uK)."""
    import healpy as hp
    import numpy as np

    l = np.arange(lmax + 1, dtype=float)
    cl = np.zeros(lmax + 1)
    cl[2:] = 2 * np.pi * 1000.0 / (l[2:] * (l[2:] + 1))
    rng = np.random.default_rng(seed)
    alm = np.zeros((3, hp.Alm.getsize(lmax)), dtype=np.complex128)
    for comp, scale in enumerate((1.0, 0.05, 0.005)):
        for m in range(lmax + 1):
            ls = np.arange(m, lmax + 1)
            idx = hp.Alm.getidx(lmax, ls, m)
            sd = np.sqrt(cl[ls] * scale)
            if m == 0:
                alm[comp, idx] = sd * rng.standard_normal(len(ls))
            else:
                alm[comp, idx] = sd * (rng.standard_normal(len(ls)) + 1j * rng.standard_normal(len(ls))) / np.sqrt(2)
    return alm


def table1_pointing(nside):
    import healpy as hp
    import numpy as np

    theta, phi = hp.pix2ang(nside, np.arange(12 * nside * nside))
    rows = []
    for zeta in (0.0, -np.pi / 2):  # the PSB pair
        for psi in np.radians([0.0, 45.0, 90.0]):
            rows.append(np.stack([theta, phi, np.full_like(theta, psi + zeta)], axis=1))
    ptg = np.concatenate(rows)
    ptg[:, 2] = np.mod(ptg[:, 2] + 2 * np.pi, 4 * np.pi) - 2 * np.pi  # within ducc0's [-2pi, 2pi]
    return ptg


def ducc0_table1(lmax, epsilon, nthreads):
    import ducc0
    import numpy as np

    alm = random_sky_alm(lmax, seed=1)
    blm = gaussian_blm(lmax, np.radians(FWHM_DEG))
    ptg = table1_pointing(TABLE1_NSIDE)
    t0 = time.perf_counter()
    interp = ducc0.totalconvolve.Interpolator(alm, blm, False, lmax, 2, epsilon=epsilon, nthreads=nthreads)
    t1 = time.perf_counter()
    tod = interp.interpol(ptg)
    t2 = time.perf_counter()
    assert tod.shape[-1] == len(ptg) and np.all(np.isfinite(tod))
    return len(ptg), t1 - t0, t2 - t1


def run_pisco_bench(pisco, backend, radii):
    """Runs pisco-vk bench; returns (its output, [(rho, conv_s, setup_s)])."""
    cmd = [pisco, "bench", "-b", backend, "--rho-max"] + [str(r) for r in radii]
    print("$ " + " ".join(cmd), flush=True)
    out = subprocess.run(cmd, capture_output=True, text=True)
    if out.returncode != 0:
        raise SystemExit(f"pisco-vk bench failed ({out.returncode}):\n{out.stdout}{out.stderr}")
    rows = []
    for line in out.stdout.splitlines():
        m = re.match(r"\s*([\d.]+)\s+([\d.]+)\s+([\d.]+)\s+([\d.]+)\s+([\d.e+-]+)", line)
        if m:
            rows.append((float(m.group(1)), float(m.group(4)), float(m.group(3))))
    return out.stdout, rows


def check_against_pisco(pisco, lmax, epsilon, nthreads):
    """pisco's cpu TOD against ducc0's on the same band-limited sky; returns the relative RMS difference."""
    import ducc0
    import h5py
    import healpy as hp
    import numpy as np

    alm = random_sky_alm(lmax, seed=2)
    maps = hp.alm2map(alm, TABLE1_NSIDE, lmax=lmax, pol=True)
    with tempfile.TemporaryDirectory() as tmp:
        hp.write_map(os.path.join(tmp, "sky.fits"), maps, column_units="uK_CMB", dtype=np.float64)
        with open(os.path.join(tmp, "check.toml"), "w") as f:
            f.write(f"""[sky]
file = "sky.fits"
[beams.main]
type = "gaussian"
fwhm_deg = {FWHM_DEG}
rho_max_deg = 5
[[focal_plane.detectors]]
name = "d"
beam = "main"
[scan]
type = "pixel_centres"
nside = 16
psi_deg = [0, 45, 90]
[engine]
backend = "cpu"
[output]
dir = "{os.path.join(tmp, 'out')}"
tod_pointing = true
maps = false
spectra = false
plots = false
""")
        run = subprocess.run([pisco, "run", os.path.join(tmp, "check.toml"), "-q", "--no-plots"],
                             capture_output=True, text=True)
        if run.returncode != 0:
            raise SystemExit(f"pisco-vk run failed ({run.returncode}):\n{run.stdout}{run.stderr}")
        with h5py.File(os.path.join(tmp, "out", "tod.h5"), "r") as h:
            g = h["d"]
            ptg = np.stack([g["theta"][:], g["phi"][:], g["psi"][:]], axis=1)
            pisco_tod = g["signal"][:]
    ptg[:, 1] = np.mod(ptg[:, 1], 2 * np.pi)
    blm = gaussian_blm(lmax, np.radians(FWHM_DEG))
    interp = ducc0.totalconvolve.Interpolator(alm, blm, False, lmax, 2, epsilon=epsilon, nthreads=nthreads)
    ducc_tod = 0.5 * interp.interpol(ptg)[0]  # pisco's ideal detector measures (I + Q c + U s) / 2
    diff = pisco_tod - ducc_tod
    rel = np.sqrt(np.mean(diff ** 2) / np.mean(ducc_tod ** 2))
    # The same with the sign of the polarization part flipped: a convention error would show here.
    interp_t = ducc0.totalconvolve.Interpolator(alm[:1], blm[:1], False, lmax, 2, epsilon=epsilon, nthreads=nthreads)
    t_only = 0.5 * interp_t.interpol(ptg)[0]
    flipped = np.sqrt(np.mean((pisco_tod - (2 * t_only - ducc_tod)) ** 2) / np.mean(ducc_tod ** 2))
    return len(ptg), rel, flipped


def main():
    here = os.path.dirname(os.path.abspath(__file__))
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--pisco", default=os.path.join(here, "..", "build", "tools", "pisco-vk"),
                    help="the pisco-vk binary (default: build/tools/pisco-vk)")
    ap.add_argument("-b", "--backend", default="auto", help="pisco backend for the bench (default: auto)")
    ap.add_argument("--rho-max", type=float, nargs="+", default=[5.0, 10.0],
                    help="pisco disc radii in degrees (default: 5 10; Table 1: 5 7.5 10 15 20 25 30)")
    ap.add_argument("--lmax", type=int, default=3 * TABLE1_NSIDE - 1, help="sky and beam lmax (383)")
    ap.add_argument("--epsilon", type=float, default=1e-5, help="ducc0 accuracy (1e-5)")
    ap.add_argument("--threads", type=int, default=os.cpu_count(), help="ducc0 threads (all cores)")
    ap.add_argument("--no-bench", action="store_true", help="skip pisco-vk bench")
    ap.add_argument("--no-check", action="store_true", help="skip the TOD comparison with pisco's cpu backend")
    ap.add_argument("--venv", default=os.path.expanduser("~/.cache/pisco/ducc0-venv"),
                    help="virtual environment for ducc0, numpy, healpy, h5py")
    args = ap.parse_args()
    ensure_venv(args.venv)
    import ducc0

    pisco = os.path.abspath(args.pisco)
    print(f"ducc0 {ducc0.__version__}, {args.threads} threads of {os.cpu_count()} cores; "
          f"lmax {args.lmax}, kmax 2, epsilon {args.epsilon:g}, FWHM {FWHM_DEG} deg", flush=True)
    n, setup, interp = ducc0_table1(args.lmax, args.epsilon, args.threads)
    print(f"ducc0 Table 1: {n} samples, set-up {setup:.3f} s, interpolation {interp:.3f} s, "
          f"{n / interp:.3e} samples/s (interpolation), {n / (setup + interp):.3e} samples/s (with set-up)",
          flush=True)

    if not args.no_bench:
        text, rows = run_pisco_bench(pisco, args.backend, args.rho_max)
        print(text, end="")
        print(f"{'':10}{'rho_max':>8} {'samples/s':>12} {'with set-up':>12}   (ducc0: {n / interp:.3e}, "
              f"{n / (setup + interp):.3e})")
        for rho, conv, pset in rows:
            print(f"{'pisco':10}{rho:8.1f} {n / conv:12.3e} {n / (conv + pset):12.3e}   "
                  f"pisco/ducc0 {interp / conv:.3g} (interpolation), {(setup + interp) / (conv + pset):.3g} (with set-up)")

    if not args.no_check:
        m, rel, flipped = check_against_pisco(pisco, args.lmax, args.epsilon, args.threads)
        print(f"check: pisco cpu vs ducc0 on one band-limited sky, {m} samples (NSIDE 16 pixel centres x 3 psi, "
              f"rho_max 5 deg): relative RMS difference {rel:.2e} (polarization sign flipped: {flipped:.2e})")
        if not rel < 1e-2 or not rel < flipped:
            raise SystemExit("check FAILED: pisco and ducc0 disagree beyond pixelization")


if __name__ == "__main__":
    main()
