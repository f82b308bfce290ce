#!/usr/bin/python3
"""ctest python.*: one pytest file of the Python package's tests, in BUILD/python-venv.

The package is the one built in the build tree (BUILD/python/pisco: the module and copies of
python/pisco/*), found through PYTHONPATH. Exit status: pytest's (0 passed, else failed; "no test
collected" is a failure), or 77 (skipped, the reason printed) when the environment cannot be
completed because PyPI is unreachable.

Usage: run_pytest.py --build BUILD_DIR [--not-built] TEST_FILE [PYTEST_ARGS...]
--not-built: the tree was configured without the package (PISCO_BUILD_PYTHON=OFF, or nanobind was
missing): skipped when PyPI is unreachable, else a failure saying how to build it.
"""

import argparse
import os
import subprocess
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import python_env as test_venv  # noqa: E402


def log(message):
    print(f"run_pytest: {message}", flush=True)


def main():
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--build", required=True)
    p.add_argument("--not-built", action="store_true")
    p.add_argument("test")
    p.add_argument("pytest_args", nargs=argparse.REMAINDER)
    args = p.parse_args()
    build = os.path.abspath(args.build)
    venv = os.path.join(build, "python-venv")
    try:
        test_venv.ensure_venv(venv, log=log)
        test_venv.ensure_venv(venv, test_venv.WITHOUT_DEPENDENCIES, log=log, no_deps=True)
    except test_venv.Unavailable as exc:
        log(f"{'SKIPPED' if exc.skip else 'FAILED'}: {exc}")
        return test_venv.SKIP if exc.skip else 1
    if args.not_built:
        log(f"FAILED: {build} was configured without the Python package; configure it with "
            f"-DPISCO_BUILD_PYTHON=ON -DPython_EXECUTABLE={venv}/bin/python and build "
            "(scripts/run-tests.sh does both)")
        return 1
    env = dict(os.environ)
    env["PYTHONPATH"] = os.path.join(build, "python") + (os.pathsep + env["PYTHONPATH"] if env.get("PYTHONPATH") else "")
    env.setdefault("TOAST_LOGLEVEL", "WARNING")
    env.setdefault("OMP_NUM_THREADS", "2")
    env["PISCO_TEST_BUILD"] = build
    # A temporary directory of the suite's own: suites run in parallel, and pytest's shared numbered
    # directories are pruned by whichever session starts next.
    basetemp = os.path.join(build, "pytest-tmp", os.path.splitext(os.path.basename(os.path.normpath(args.test)))[0])
    os.makedirs(os.path.dirname(basetemp), exist_ok=True)
    command = [test_venv.python_of(venv), "-m", "pytest", "-q", "-p", "no:cacheprovider", "-rs",
               "--basetemp", basetemp, args.test] + args.pytest_args
    done = subprocess.run(command, env=env, cwd=build)
    if done.returncode == 5:
        log("FAILED: pytest collected no test")
        return 1
    return done.returncode


if __name__ == "__main__":
    sys.exit(main())
