"""PISCO-VK inside a framework that owns its MPI communicator (docs/scaling.md): one engine per rank
under mpi4py, the detectors shared out between 2 and 3 ranks, give the TODs of one process bit for bit."""

import os
import shutil
import subprocess
import sys

import numpy as np
import pytest

import pisco
from pisco import deg

HERE = os.path.dirname(os.path.abspath(__file__))


def single_process_tods():
    rng = np.random.default_rng(1)
    nside = 32
    sky = pisco.Sky.from_maps(rng.normal(size=(3, 12 * nside * nside)), units="uK_CMB")
    beam = pisco.Beamsor.gaussian(2 * deg, rho_max=5 * deg)
    fp = pisco.FocalPlane()
    for i in range(5):
        fp.add(f"d{i}", zeta=0.3 * i, offset=pisco.offset_quat(0.5 * i * deg, -0.3 * i * deg, 0.1 * i))
    n = 400
    theta = np.arccos(rng.uniform(-1, 1, n))
    phi = rng.uniform(0, 2 * np.pi, n)
    psi = rng.uniform(-np.pi, np.pi, n)
    with pisco.Engine(sky, beam, fp, backend="cpu", threads=1) as engine:
        return np.array([engine.convolve(d, theta=theta, phi=phi, psi=psi) for d in range(len(fp))])


@pytest.mark.parametrize("ranks", [2, 3])
def test_one_engine_per_rank_under_mpi4py(tmp_path, ranks):
    mpirun = shutil.which("mpirun")
    assert mpirun, "mpirun not found (scripts/setup.sh installs openmpi-bin)"
    out = tmp_path / "tods.npy"
    env = dict(os.environ, OMPI_ALLOW_RUN_AS_ROOT="1", OMPI_ALLOW_RUN_AS_ROOT_CONFIRM="1", OMPI_MCA_rmaps_base_oversubscribe="1")
    cmd = [mpirun, "--oversubscribe", "-n", str(ranks), "-x", "PYTHONPATH", sys.executable,
           os.path.join(HERE, "mpi_worker.py"), str(out)]
    run = subprocess.run(cmd, env=env, capture_output=True, text=True, timeout=300)
    assert run.returncode == 0, run.stdout + run.stderr
    got = np.load(out)
    want = single_process_tods()
    assert got.shape == want.shape
    np.testing.assert_array_equal(got, want)
