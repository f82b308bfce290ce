#!/usr/bin/python3
"""The virtual environment of the python tests: BUILD/python-venv with the packages from PyPI.

Standard library only; run with the system Python (Debian's python3, with python3-venv and
python3-dev). Creates the environment on first use and installs what is missing; an environment
that already imports everything is left alone (no network). Exit status, as a script:

- 0: the environment is complete;
- 77: PyPI could not be reached within 5 s and packages are missing (the reason is printed):
  the python tests skip;
- 1: anything else (pip failed although PyPI answered, no venv module): the python tests fail.

Usage: python_env.py VENV_DIR
"""

import os
import subprocess
import sys
import time
import urllib.error
import urllib.request

SKIP = 77
# pip names -> import names. Binary wheels only: nothing is compiled here.
PACKAGES = {
    "numpy": "numpy",
    "h5py": "h5py",
    "astropy": "astropy",
    "healpy": "healpy",
    "toast": "toast",
    "ducc0": "ducc0",
    "litebird_sim": "litebird_sim",
    "matplotlib": "matplotlib",
    "pytest": "pytest",
    "nanobind": "nanobind",
    "scikit-build-core": "scikit_build_core",
    "mpi4py": "mpi4py",
}
# Installed without their declared dependencies, which pin what the packages above need newer
# (grasp2alm 0.1.2 asks for numpy < 2 and pytest < 9); what they import is installed above.
WITHOUT_DEPENDENCIES = {
    "grasp2alm==0.1.2": "grasp2alm",
}
REGISTRY = "https://pypi.org/simple/pip/"


# PISCO_REQUIRE_PEERS=1 (set by .ci/run): nothing skips for want of PyPI or of a peer package; the run
# fails instead, saying what is missing (docs/validation.md, "What a run must not skip").
REQUIRED = os.environ.get("PISCO_REQUIRE_PEERS") == "1"


class Unavailable(Exception):
    """The environment cannot be completed; .skip says whether that is PyPI's absence (never when
    PISCO_REQUIRE_PEERS=1: then the tests fail)."""

    def __init__(self, message, skip):
        if skip and REQUIRED:
            message += " (PISCO_REQUIRE_PEERS=1: a run that requires every peer package fails instead of skipping)"
        super().__init__(message)
        self.skip = skip and not REQUIRED


def python_of(venv):
    return os.path.join(venv, "bin", "python")


def missing_modules(venv, modules):
    """The modules the environment cannot find (found without importing them: a fast probe)."""
    python = python_of(venv)
    if not os.access(python, os.X_OK):
        return list(modules)
    probe = (
        "import importlib.util, sys\n"
        "print(' '.join(m for m in sys.argv[1:] if importlib.util.find_spec(m) is None))\n"
    )
    done = subprocess.run([python, "-c", probe] + list(modules), capture_output=True, text=True)
    if done.returncode != 0:
        return list(modules)
    return done.stdout.split()


def registry_reachable():
    """None when PyPI answers within 5 s, else the reason."""
    request = urllib.request.Request(REGISTRY, method="HEAD")
    try:
        with urllib.request.urlopen(request, timeout=5):
            return None
    except (urllib.error.URLError, OSError, ValueError) as exc:
        return f"{REGISTRY} unreachable ({getattr(exc, 'reason', exc)})"


def ensure_venv(venv, packages=PACKAGES, log=print, no_deps=False):
    """Creates or completes the environment; raises Unavailable when it cannot."""
    missing = missing_modules(venv, packages.values())
    if not missing:
        return
    names = [p for p, m in packages.items() if m in missing]
    reason = registry_reachable()
    if reason is not None:
        raise Unavailable(f"{reason}; the python tests need {', '.join(names)} from PyPI in {venv}", skip=True)
    t0 = time.perf_counter()
    if not os.access(python_of(venv), os.X_OK):
        made = subprocess.run([sys.executable, "-m", "venv", venv], capture_output=True, text=True)
        if made.returncode != 0:
            raise Unavailable(
                f"cannot create a virtual environment with {sys.executable} -m venv (python3-venv): "
                f"{made.stderr.strip()[-500:]}",
                skip=False,
            )
    env = dict(os.environ, PIP_DISABLE_PIP_VERSION_CHECK="1")
    env.pop("PIP_DEFAULT_TIMEOUT", None)
    log(f"installing {', '.join(names)} into {venv} from PyPI")
    pip = [python_of(venv), "-m", "pip", "install", "--quiet", "--timeout", "5", "--retries", "0",
           "--only-binary=:all:"] + (["--no-deps"] if no_deps else []) + names
    installed = subprocess.run(pip, capture_output=True, text=True, env=env)
    still = missing_modules(venv, packages.values())
    if installed.returncode != 0 or still:
        tail = (installed.stdout + installed.stderr).strip()[-1500:]
        raise Unavailable(f"pip could not install {', '.join(names)} into {venv}: {tail}", skip=False)
    log(f"installed {', '.join(names)} into {venv} in {time.perf_counter() - t0:.0f} s")


def main():
    if len(sys.argv) != 2:
        print(__doc__.strip().splitlines()[-1], file=sys.stderr)
        return 2
    venv = os.path.abspath(sys.argv[1])
    try:
        log = lambda m: print(f"python-venv: {m}", flush=True)  # noqa: E731
        ensure_venv(venv, log=log)
        ensure_venv(venv, WITHOUT_DEPENDENCIES, log=log, no_deps=True)
    except Unavailable as exc:
        print(f"python-venv: {'SKIPPED' if exc.skip else 'FAILED'}: {exc}", flush=True)
        return SKIP if exc.skip else 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
