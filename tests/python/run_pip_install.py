#!/usr/bin/python3
"""ctest python.pip_install: `pip install .` at the repository root, as a user runs it.

Runs with the system Python (standard library only):

1. a virtual environment at BUILD/pip-venv with the system's site packages (Debian's numpy), created
   on the first run and reused afterwards;
2. ``pip install SOURCE`` into it: pip fetches scikit-build-core and nanobind from PyPI into its
   isolated build environment, and scikit-build-core builds libpisco and the module with CMake in
   SOURCE/build/pip/<wheel tag> (pyproject.toml; kept between runs, so later runs rebuild only what
   changed). Where PyPI cannot be reached within 5 s the test is skipped (exit status 77), saying why;
3. in a scratch directory (not the source tree, so that only the installed package can be imported):
   ``import pisco`` must come from the environment's site-packages, ``pisco.devices()`` must list the
   vulkan backend as available, and a small sky convolved by the installed package's cpu, simd (where
   built) and vulkan backends must agree with one another (relative RMS below 1e-5, the float32
   backends' bar) and be non-trivial;
4. ``pip install -r examples/python/requirements.txt`` and each script of examples/python/ with its
   defaults, from a scratch directory, exactly as README.md's "Python" section runs them: each must
   end well and draw its map.

Usage: run_pip_install.py --build BUILD_DIR --source SOURCE_DIR
"""

import argparse
import os
import subprocess
import sys
import tempfile
import time

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import python_env  # noqa: E402  (the PyPI probe shared by the python tests)

CHECK = r"""
import os, sys
import numpy as np
import pisco

venv = sys.argv[1]
where = os.path.realpath(pisco.__file__)
assert where.startswith(os.path.realpath(venv)), f"pisco imported from {where}, not from {venv}"
backends = {b.name: b for b in pisco.devices()}
print("installed:", where)
for b in backends.values():
    print("  ", b)
assert backends["cpu"].available, backends["cpu"]
assert "vulkan" in backends and backends["vulkan"].available, backends.get("vulkan")

nside = 32
rng = np.random.default_rng(5)
sky = pisco.Sky.from_maps(rng.normal(size=(3, 12 * nside * nside)), units="uK_CMB")
deg = np.pi / 180
beam = pisco.Beamsor.gaussian(3 * deg, rho_max=7.5 * deg)
fp = pisco.FocalPlane()
fp.add_pair("p", zeta=0.3)
n = 500
theta = np.arccos(rng.uniform(-1, 1, n))
phi = rng.uniform(0, 2 * np.pi, n)
psi = rng.uniform(-np.pi, np.pi, n)
names = [b for b in ("cpu", "simd", "vulkan") if b in backends and backends[b].available]
tods = {}
for b in names:
    with pisco.Engine(sky, beam, fp, backend=b) as engine:
        tods[b] = np.concatenate([engine.convolve(d, theta, phi, psi) for d in range(2)])
ref = tods["cpu"]
rms = np.sqrt(np.mean(ref ** 2))
assert rms > 0.01, rms
for b in names:
    err = np.sqrt(np.mean((tods[b] - ref) ** 2)) / rms
    print(f"  {b}: relative RMS difference from cpu {err:.2e}")
    assert err < 1e-5, (b, err)
print("ok")
"""


def log(message):
    print(f"python.pip_install: {message}", flush=True)


def main():
    parser = argparse.ArgumentParser(description=__doc__.strip().splitlines()[0])
    parser.add_argument("--build", required=True)
    parser.add_argument("--source", required=True)
    args = parser.parse_args()
    venv = os.path.join(os.path.abspath(args.build), "pip-venv")
    python = python_env.python_of(venv)

    reason = python_env.registry_reachable()
    if reason is not None:
        log(f"SKIPPED: {reason}; pip install . fetches scikit-build-core and nanobind from PyPI")
        return python_env.SKIP
    if not os.access(python, os.X_OK):
        made = subprocess.run([sys.executable, "-m", "venv", "--system-site-packages", venv],
                              capture_output=True, text=True)
        if made.returncode != 0:
            log(f"FAILED: cannot create {venv} with {sys.executable} -m venv: {made.stderr.strip()[-500:]}")
            return 1

    env = dict(os.environ, PIP_DISABLE_PIP_VERSION_CHECK="1")
    env.pop("PYTHONPATH", None)
    t0 = time.perf_counter()
    log(f"pip install {args.source} into {venv}")
    installed = subprocess.run([python, "-m", "pip", "install", "--quiet", "--timeout", "5", "--retries", "0",
                                args.source], capture_output=True, text=True, env=env)
    if installed.returncode != 0:
        log(f"FAILED: pip install exited with {installed.returncode}:\n"
            f"{(installed.stdout + installed.stderr).strip()[-3000:]}")
        return 1
    log(f"installed in {time.perf_counter() - t0:.0f} s")

    with tempfile.TemporaryDirectory(prefix="pisco-pip-") as scratch:
        checked = subprocess.run([python, "-c", CHECK, venv], cwd=scratch, capture_output=True, text=True, env=env)
    print(checked.stdout, end="")
    if checked.returncode != 0:
        log(f"FAILED: the installed package:\n{checked.stderr.strip()[-3000:]}")
        return 1

    # The examples, as README.md's "Python" runs them: their requirements into the same environment,
    # then each script with its defaults, from a scratch directory.
    requirements = os.path.join(args.source, "examples", "python", "requirements.txt")
    log(f"pip install -r {requirements}")
    deps = subprocess.run([python, "-m", "pip", "install", "--quiet", "--timeout", "5", "--retries", "0",
                           "-r", requirements], capture_output=True, text=True, env=env)
    if deps.returncode != 0:
        log(f"FAILED: pip install -r exited with {deps.returncode}:\n{(deps.stdout + deps.stderr).strip()[-3000:]}")
        return 1
    for script, out in (("toast_pipeline.py", "pisco-toast-example"),
                        ("litebird_sim_pipeline.py", "pisco-litebird-example")):
        with tempfile.TemporaryDirectory(prefix="pisco-example-") as scratch:
            t0 = time.perf_counter()
            ran = subprocess.run([python, os.path.join(args.source, "examples", "python", script)], cwd=scratch,
                                 capture_output=True, text=True, env=env, timeout=600)
            png = os.path.join(scratch, out, "binned_map.png")
            if ran.returncode != 0 or not os.path.exists(png) or os.path.getsize(png) < 10000:
                log(f"FAILED: examples/python/{script} (exit {ran.returncode}, {png} "
                    f"{'missing' if not os.path.exists(png) else 'written'}):\n{(ran.stdout + ran.stderr).strip()[-3000:]}")
                return 1
            log(f"examples/python/{script}: {ran.stdout.strip().splitlines()[-1]} ({time.perf_counter() - t0:.0f} s)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
