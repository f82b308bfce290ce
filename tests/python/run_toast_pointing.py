#!/usr/bin/python3
"""ctest python.toast_pointing: PISCO-VK's detector pointing against TOAST 3's own.

Runs with the system Python (standard library only):

1. the python tests' virtual environment at BUILD/python-venv (python_env.py: TOAST 3,
   h5py, numpy, astropy and the rest from PyPI, binary wheels only), created on
   the first run and reused afterwards; when packages are missing and PyPI
   cannot be reached within 5 s, the test is skipped (exit status 77) with the
   reason;
2. tools/toast_pointing.py in that environment: TOAST's focal plane
   (focalplane.h5), and one ground and one satellite observation with TOAST's
   boresight quaternions and its expanded detector pointing and Stokes weights;
3. for each observation, ``pisco-vk run`` on a tiny sky with that focal plane
   (``[focal_plane] file``) and that boresight (``[scan] type = "file"``),
   writing the detectors' pointing into tod.h5;
4. compare_toast_pointing.py in the environment: line of sight, polarization
   orientation and Stokes weights, detector by detector and sample by sample,
   to 1e-10 rad.

Usage: run_toast_pointing.py --build BUILD_DIR --pisco-vk PISCO_VK --source SOURCE_DIR
"""

import argparse
import os
import shutil
import subprocess
import sys
import tempfile
import time

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import python_env  # noqa: E402  (the environment shared by the python tests)

# What this test needs, installed here when missing (scripts/run-tests.sh installs all of python_env.PACKAGES).
PACKAGES = {"toast": "toast", "h5py": "h5py", "numpy": "numpy", "astropy": "astropy"}


def log(message):
    print(f"python.toast_pointing: {message}", flush=True)


def skip(reason):
    log(f"SKIPPED: {reason}")
    sys.exit(python_env.SKIP)


def venv_python(venv):
    return python_env.python_of(venv)


def ensure_venv(venv):
    try:
        python_env.ensure_venv(venv, packages=PACKAGES, log=log)
    except python_env.Unavailable as exc:
        if exc.skip:
            skip(str(exc))
        log(f"FAILED: {exc}")
        sys.exit(1)


def simulation_toml(focalplane, boresight):
    return f"""# python.toast_pointing: TOAST's focal plane and boresight through pisco-vk.
[sky]
nside = 16
lmax = 32
seed = 1

[beams.main]
type = "gaussian"
fwhm_deg = 1.0
rho_max_deg = 4.0

[focal_plane]
file = "{focalplane}"
beam = "main"

[scan]
type = "file"
file = "{boresight}"

[engine]
backend = "cpu"

[output]
tod = true
tod_pointing = true
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
    ensure_venv(venv)
    python = venv_python(venv)
    here = os.path.dirname(os.path.abspath(__file__))
    work = tempfile.mkdtemp(prefix="pisco-toast-pointing-")
    ok = False
    try:
        env = dict(os.environ, TOAST_LOGLEVEL="WARNING", OMP_NUM_THREADS="1")
        exported = subprocess.run(
            [python, os.path.join(args.source, "tools", "toast_pointing.py"), "--outdir", work,
             "--pol-leakage", "0.1"],
            capture_output=True, text=True, env=env)
        if exported.returncode != 0:
            log("tools/toast_pointing.py failed:\n" + exported.stdout + exported.stderr)
            return 1
        log(exported.stdout.strip())
        focalplane = os.path.join(work, "focalplane.h5")
        for kind in ("ground", "satellite"):
            boresight = os.path.join(work, f"toast_{kind}.h5")
            config = os.path.join(work, f"{kind}.toml")
            with open(config, "w") as f:
                f.write(simulation_toml(focalplane, boresight))
            out = os.path.join(work, f"pisco_{kind}")
            ran = subprocess.run([args.pisco_vk, "run", config, "-o", out, "-q", "--no-plots"],
                                 capture_output=True, text=True)
            if ran.returncode != 0:
                log(f"pisco-vk run {config} failed (status {ran.returncode}):\n" + ran.stdout + ran.stderr)
                return 1
        pairs = []
        for kind in ("ground", "satellite"):
            pairs += ["--pair", kind, os.path.join(work, f"toast_{kind}.h5"), os.path.join(work, f"pisco_{kind}", "tod.h5")]
        compared = subprocess.run(
            [python, os.path.join(here, "compare_toast_pointing.py"), "--tolerance", "1e-10"] + pairs,
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
