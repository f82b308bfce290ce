#!/usr/bin/python3
"""ctest python.masked_spectra: makes the spectra environment (tools/spectra_env.py: NaMaster from PyPI
into <build>/spectra-venv; skips with status 77, saying why, when PyPI cannot be reached) and runs
check_masked_spectra.py in it."""
import os
import subprocess
import sys

here = os.path.dirname(os.path.abspath(__file__))
root = os.path.normpath(os.path.join(here, "..", ".."))
build = sys.argv[1] if len(sys.argv) > 1 else os.path.join(root, "build")
venv = os.path.join(build, "spectra-venv")
status = subprocess.run([sys.executable, os.path.join(root, "tools", "spectra_env.py"), venv]).returncode
if status != 0:
    sys.exit(status)
sys.exit(subprocess.run([os.path.join(venv, "bin", "python"), os.path.join(here, "check_masked_spectra.py"),
                         os.path.join(build, "masked-spectra-test")]).returncode)
