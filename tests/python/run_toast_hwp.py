#!/usr/bin/python3
"""ctest python.toast_hwp: PISCO-VK's ideal half-wave plate against TOAST 3's own Stokes weights.

Runs with the system Python (standard library only):

1. the python tests' virtual environment at BUILD/python-venv (python_env.py; TOAST 3,
   h5py, numpy, astropy and healpy from PyPI, binary wheels only); when packages are
   missing and PyPI cannot be reached within 5 s, the test is skipped (exit status 77)
   with the reason;
2. tools/toast_pointing.py --hwp-rpm 46 in that environment: TOAST's focal plane
   (focalplane.h5, its detectors turned to gamma values that are not multiples of
   45 deg by --gamma-step) and one ground and one satellite observation with an ideal
   plate turning at 46 rpm: TOAST's boresight quaternions (``boresight``), its plate
   angle per sample (``hwp_angle``) and its Stokes weights through the plate
   (StokesWeights with hwp_angle, mode IQU, COSMO) per detector;
3. three uniform skies, I = 1, Q = 1 and U = 1 (NSIDE 256, healpy), and for each
   observation and sky ``pisco-vk run`` with that focal plane, that boresight file,
   ``[hwp] model = "ideal"`` (the angles from the file's hwp_angle), a narrow Gaussian
   beam (FWHM 0.5 deg, rho_max 1.5 deg) and ``normalization = "per_sample"``, so that
   each TOD is TOAST's I, Q or U weight;
4. compare_toast_hwp.py: the three TOD against TOAST's three weight columns, sample by
   sample, to 1e-3 (the I weight to 1e-12), and the same TOD against the weights of
   the plausible convention errors, each of which must miss by more than 0.1.

Why 1e-3 and not 1e-10: a uniform Q (or U) map is uniform in each pixel's own basis,
which turns across the beam by about the beam's width times cot(theta); a beam of
sigma = 0.21 deg measures cos 2 chi to 1 - 2 sigma^2 cot^2(theta), 1e-4 at
theta = 28 deg, the satellite scan's closest approach to the pole. A convention error
(the plate angle's sense, gamma's sign or absence, a factor 2, the U sign) is an O(1)
difference.

Usage: run_toast_hwp.py --build BUILD_DIR --pisco-vk PISCO_VK --source SOURCE_DIR [--keep]
"""

import argparse
import os
import shutil
import subprocess
import sys
import tempfile
import time

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import python_env  # noqa: E402

NAME = "python.toast_hwp"
PACKAGES = {"numpy": "numpy", "h5py": "h5py", "astropy": "astropy", "healpy": "healpy", "toast": "toast"}
SKIES = {"I": (1.0, 0.0, 0.0), "Q": (0.0, 1.0, 0.0), "U": (0.0, 0.0, 1.0)}
# The satellite's spin and precession opening angles keep every line of sight at least 28 deg
# from the poles (see the docstring).
TOAST_ARGS = ["--hwp-rpm", "46", "--gamma-step", "10", "--pol-leakage", "0.1",
              "--spin-angle", "20", "--prec-angle", "30"]


def log(message):
    print(f"{NAME}: {message}", flush=True)


def write_skies(python, work):
    code = (
        "import sys, numpy as np, healpy as hp\n"
        "n = 12 * 256 ** 2\n"
        "for name, iqu in zip(sys.argv[1::2], sys.argv[2::2]):\n"
        "    v = [float(x) for x in iqu.split(',')]\n"
        "    hp.write_map(name, [np.full(n, x, dtype=np.float32) for x in v], dtype=np.float32,\n"
        "                 column_units='K', overwrite=True)\n"
    )
    argv = []
    for stokes, iqu in SKIES.items():
        argv += [os.path.join(work, f"sky_{stokes}.fits"), ",".join(str(x) for x in iqu)]
    return subprocess.run([python, "-c", code] + argv, capture_output=True, text=True)


def simulation_toml(sky, focalplane, boresight, out):
    return f"""# python.toast_hwp: TOAST's focal plane, boresight and plate angles through pisco-vk.
[sky]
file = "{sky}"

[beams.main]
type = "gaussian"
fwhm_deg = 0.5
rho_max_deg = 1.5

[focal_plane]
file = "{focalplane}"
beam = "main"

[scan]
type = "file"
file = "{boresight}"

[hwp]
model = "ideal"

[engine]
backend = "cpu"
normalization = "per_sample"

[output]
dir = "{out}"
tod = true
tod_pointing = false
maps = false
spectra = false
plots = false
"""


def main():
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--build", required=True, help="the build directory (the environment goes in python-venv)")
    p.add_argument("--pisco-vk", required=True, help="the pisco-vk executable")
    p.add_argument("--source", required=True, help="the source directory")
    p.add_argument("--keep", action="store_true", help="keep the working directory")
    args = p.parse_args()

    t0 = time.perf_counter()
    venv = os.path.join(os.path.abspath(args.build), "python-venv")
    try:
        python_env.ensure_venv(venv, packages=PACKAGES, log=log)
    except python_env.Unavailable as exc:
        log(f"{'SKIPPED' if exc.skip else 'FAILED'}: {exc}")
        return python_env.SKIP if exc.skip else 1
    python = python_env.python_of(venv)
    here = os.path.dirname(os.path.abspath(__file__))
    work = tempfile.mkdtemp(prefix="pisco-toast-hwp-")
    ok = False
    try:
        env = dict(os.environ, TOAST_LOGLEVEL="WARNING", OMP_NUM_THREADS="1")
        exported = subprocess.run(
            [python, os.path.join(args.source, "tools", "toast_pointing.py"), "--outdir", work] + TOAST_ARGS,
            capture_output=True, text=True, env=env)
        if exported.returncode != 0:
            log("tools/toast_pointing.py failed:\n" + exported.stdout + exported.stderr)
            return 1
        log(exported.stdout.strip())
        skies = write_skies(python, work)
        if skies.returncode != 0:
            log("writing the uniform skies failed:\n" + skies.stdout + skies.stderr)
            return 1
        focalplane = os.path.join(work, "focalplane.h5")
        pairs = []
        for kind in ("ground", "satellite"):
            boresight = os.path.join(work, f"toast_{kind}.h5")
            tods = []
            for stokes in SKIES:
                config = os.path.join(work, f"{kind}_{stokes}.toml")
                out = os.path.join(work, f"pisco_{kind}_{stokes}")
                with open(config, "w") as f:
                    f.write(simulation_toml(os.path.join(work, f"sky_{stokes}.fits"), focalplane, boresight, out))
                ran = subprocess.run([args.pisco_vk, "run", config, "-q", "--no-plots"],
                                     capture_output=True, text=True)
                if ran.returncode != 0:
                    log(f"pisco-vk run {config} failed (status {ran.returncode}):\n" + ran.stdout + ran.stderr)
                    return 1
                tods.append(os.path.join(out, "tod.h5"))
            pairs += ["--observation", kind, boresight] + tods
        compared = subprocess.run(
            [python, os.path.join(here, "compare_toast_hwp.py"), "--tolerance", "1e-3"] + pairs,
            capture_output=True, text=True)
        sys.stdout.write(compared.stdout)
        sys.stdout.write(compared.stderr)
        ok = compared.returncode == 0
        log(f"{'passed' if ok else 'FAILED'} in {time.perf_counter() - t0:.1f} s")
        return 0 if ok else 1
    finally:
        if args.keep or not ok:
            log(f"files kept in {work}")
        else:
            shutil.rmtree(work, ignore_errors=True)


if __name__ == "__main__":
    sys.exit(main())
