#!/usr/bin/python3
"""The virtual environment of the mask-corrected spectra (tools/pisco_spectra.py): NaMaster from PyPI.

NaMaster (`pymaster` on PyPI) is the field's standard pseudo-C_l library: the mask's mode coupling,
E/B purification, binning. PyPI carries it as a source distribution only; it compiles a C library that
needs GSL, FFTW, CFITSIO and HEALPix's C library (chealpix). The first three and chealpix come from
Debian (scripts/setup.sh installs libgsl-dev, libfftw3-dev, libcfitsio-dev, libchealpix-dev); the
sdist's own build script would fetch chealpix from SourceForge, so this script stages Debian's copy
where that script looks for it (`_deps/lib/libchealpix.a`; the shared library, as Debian's static
one is not position-independent) and builds the sdist from that tree.

Standard library only; run with the system Python (Debian's python3 with python3-venv). Creates VENV on
first use; an environment that already imports pymaster, healpy and numpy is left alone (no network).
Exit status: 0 ready; 77 PyPI cannot be reached (the reason is printed; tests skip); 1 anything else.

Usage: spectra_env.py VENV
"""

import glob
import os
import shutil
import subprocess
import sys
import tarfile
import tempfile
import time
import urllib.error
import urllib.request

SKIP = 77
MODULES = ["pymaster", "healpy", "numpy", "matplotlib"]
# Binary wheels for everything but pymaster itself (and fitsio, which pymaster requires and which
# PyPI carries as source; it bundles its own CFITSIO).
BINARY = ["numpy", "healpy", "ducc0", "matplotlib"]
PYMASTER = "pymaster==3.0.1"
REGISTRY = "https://pypi.org/simple/pip/"
# Debian's chealpix (libchealpix-dev): the shared library in the machine's multiarch directory.
CHEALPIX = (next(iter(sorted(glob.glob("/usr/lib/*/libchealpix.so"))), "/usr/lib/<multiarch>/libchealpix.so"),
            "/usr/include/chealpix.h")


# PISCO_REQUIRE_PEERS=1 (set by .ci/run): no skip for want of PyPI; the run fails, saying what is missing.
REQUIRED = os.environ.get("PISCO_REQUIRE_PEERS") == "1"


class Unavailable(Exception):
    def __init__(self, message, skip):
        if skip and REQUIRED:
            message += " (PISCO_REQUIRE_PEERS=1: a run that requires every peer package fails instead of skipping)"
        super().__init__(message)
        self.skip = skip and not REQUIRED


def python_of(venv):
    return os.path.join(venv, "bin", "python")


def missing_modules(venv):
    python = python_of(venv)
    if not os.access(python, os.X_OK):
        return list(MODULES)
    probe = "import importlib.util, sys\nprint(' '.join(m for m in sys.argv[1:] if importlib.util.find_spec(m) is None))\n"
    done = subprocess.run([python, "-c", probe] + MODULES, capture_output=True, text=True)
    return MODULES if done.returncode != 0 else done.stdout.split()


def registry_reachable():
    try:
        with urllib.request.urlopen(urllib.request.Request(REGISTRY, method="HEAD"), timeout=5):
            return None
    except (urllib.error.URLError, OSError, ValueError) as exc:
        return f"{REGISTRY} unreachable ({getattr(exc, 'reason', exc)})"


def run(cmd, what, env=None, cwd=None):
    done = subprocess.run(cmd, capture_output=True, text=True, env=env, cwd=cwd)
    if done.returncode != 0:
        tail = (done.stdout + done.stderr).strip()[-2000:]
        raise Unavailable(f"{what} failed: {tail}", skip=False)
    return done


def ensure(venv, log=print):
    missing = missing_modules(venv)
    if not missing:
        return
    reason = registry_reachable()
    if reason is not None:
        raise Unavailable(f"{reason}; the mask-corrected spectra need {', '.join(missing)} from PyPI in {venv}", True)
    for path in CHEALPIX:
        if not os.path.exists(path):
            raise Unavailable(f"{path} is missing: install Debian's libchealpix-dev, libgsl-dev and libfftw3-dev "
                              "(scripts/setup.sh does)", skip=False)
    t0 = time.perf_counter()
    if not os.access(python_of(venv), os.X_OK):
        run([sys.executable, "-m", "venv", venv], f"{sys.executable} -m venv {venv}")
    env = dict(os.environ, PIP_DISABLE_PIP_VERSION_CHECK="1")
    pip = [python_of(venv), "-m", "pip", "install", "--quiet", "--timeout", "30", "--retries", "1"]
    log(f"installing {', '.join(BINARY)} into {venv}")
    run(pip + ["--only-binary=:all:"] + BINARY, "pip install " + " ".join(BINARY), env)
    if "pymaster" in missing_modules(venv):
        with tempfile.TemporaryDirectory(prefix="pymaster-build-") as tmp:
            log(f"building {PYMASTER} from its PyPI source with Debian's chealpix, GSL and FFTW")
            run(pip[:3] + ["download", "--quiet", "--no-deps", "--no-binary=pymaster", "-d", tmp, PYMASTER],
                "pip download " + PYMASTER, env)
            sdist = glob.glob(os.path.join(tmp, "pymaster-*.tar.gz"))
            if not sdist:
                raise Unavailable(f"pip download {PYMASTER} left no source archive in {tmp}", skip=False)
            with tarfile.open(sdist[0]) as tar:
                tar.extractall(tmp)  # from PyPI, over HTTPS
            src = sdist[0][: -len(".tar.gz")]
            for sub in ("lib", "include", "bin"):
                os.makedirs(os.path.join(src, "_deps", sub), exist_ok=True)
            # Debian's static libchealpix.a is not position-independent and cannot go into NaMaster's
            # shared objects: its shared library stands in under both names the build links (the
            # linker reads a file's type from its content), so the module loads Debian's
            # libchealpix.so.0 at run time.
            for name in ("libchealpix.so", "libchealpix.a"):
                shutil.copy(CHEALPIX[0], os.path.join(src, "_deps", "lib", name))
            shutil.copy(CHEALPIX[1], os.path.join(src, "_deps", "include"))
            # Object files shipped in the archive would be linked as they are; start clean.
            for obj in glob.glob(os.path.join(src, "src", "*.o")) + glob.glob(os.path.join(src, "src", "*.lo")):
                os.remove(obj)
            run(pip + [src], "building " + PYMASTER, env)
    still = missing_modules(venv)
    if still:
        raise Unavailable(f"{venv} still lacks {', '.join(still)} after installing", skip=False)
    log(f"spectra environment ready in {time.perf_counter() - t0:.0f} s")


def main():
    if len(sys.argv) != 2:
        print(__doc__.strip().splitlines()[-1], file=sys.stderr)
        return 2
    venv = os.path.abspath(sys.argv[1])
    try:
        ensure(venv, log=lambda m: print(f"spectra-env: {m}", flush=True))
    except Unavailable as exc:
        print(f"spectra-env: {'SKIPPED' if exc.skip else 'FAILED'}: {exc}", flush=True)
        return SKIP if exc.skip else 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
