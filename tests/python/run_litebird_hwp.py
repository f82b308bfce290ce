#!/usr/bin/python3
"""ctest python.litebird_hwp: PISCO-VK through a half-wave plate against litebird_sim's MuellerConvolver.

docs/validation.md, H3. Runs with the system Python (standard library only):

1. the python tests' virtual environment at BUILD/python-venv (python_env.py; litebird_sim,
   ducc0, healpy, h5py and numpy from PyPI, binary wheels only); when packages are missing
   and PyPI cannot be reached within 5 s, the test is skipped (exit status 77) with the
   reason;
2. tools/hwp_compare.py --v-sky in that environment: one band-limited sky (lmax 256,
   written at NSIDE 256 for PISCO-VK), a 1.5 deg Gaussian beam, 10,000 random pointings
   and plate angles, and no plate, an ideal plate and a generic one (all 16 entries
   non-zero) through ``pisco-vk run`` (cpu) and through litebird_sim. Bars: PISCO-VK
   against litebird_sim and against the harmonic reference within 1e-4 relative RMS
   (measured: 2.6e-5, the beam's sampling and the sky's pixelization), litebird_sim
   against the reference within 1e-6 (its conventions pinned), the plate angle's other
   sense and the transposed matrix far outside the bar; on a V-only sky, PISCO-VK
   against the reference within 1e-4 (litebird_sim 0.18.0's V column is reported, not
   held: see the tool's docstring).

Usage: run_litebird_hwp.py --build BUILD_DIR --pisco-vk PISCO_VK --source SOURCE_DIR
"""

import argparse
import os
import subprocess
import sys
import time

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import python_env  # noqa: E402

NAME = "python.litebird_hwp"
PACKAGES = {"numpy": "numpy", "h5py": "h5py", "healpy": "healpy", "ducc0": "ducc0", "litebird_sim": "litebird_sim"}


def log(message):
    print(f"{NAME}: {message}", flush=True)


def main():
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--build", required=True, help="the build directory (the environment goes in python-venv)")
    p.add_argument("--pisco-vk", required=True, help="the pisco-vk executable")
    p.add_argument("--source", required=True, help="the source directory")
    args = p.parse_args()

    t0 = time.perf_counter()
    venv = os.path.join(os.path.abspath(args.build), "python-venv")
    try:
        python_env.ensure_venv(venv, packages=PACKAGES, log=log)
    except python_env.Unavailable as exc:
        log(f"{'SKIPPED' if exc.skip else 'FAILED'}: {exc}")
        return python_env.SKIP if exc.skip else 1
    env = dict(os.environ, OMP_NUM_THREADS="2", NUMBA_NUM_THREADS="2")
    command = [python_env.python_of(venv), os.path.join(args.source, "tools", "hwp_compare.py"),
               "--pisco", args.pisco_vk, "-b", "cpu", "--v-sky", "--threads", "2", "--tolerance", "1e-4"]
    done = subprocess.run(command, env=env)
    log(f"{'passed' if done.returncode == 0 else 'FAILED'} in {time.perf_counter() - t0:.1f} s")
    return 0 if done.returncode == 0 else 1


if __name__ == "__main__":
    sys.exit(main())
