"""One rank of tests/python/test_mpi.py, started by mpirun: a framework that owns its communicator
(mpi4py's COMM_WORLD here) makes one pisco.Engine per rank, each rank convolving its share of the
detectors; rank 0 gathers the TODs and saves them to the file named on the command line."""

import sys

import numpy as np
from mpi4py import MPI

import pisco
from pisco import deg


def main():
    comm = MPI.COMM_WORLD
    rank, size = comm.Get_rank(), comm.Get_size()
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
    mine = {}
    # One engine per rank, its threads shared out between the ranks of the node.
    with pisco.Engine(sky, beam, fp, backend="cpu", threads=1) as engine:
        for d in range(rank, len(fp), size):
            mine[d] = engine.convolve(d, theta=theta, phi=phi, psi=psi)
    gathered = comm.gather(mine, root=0)
    if rank == 0:
        tods = {}
        for part in gathered:
            tods.update(part)
        np.save(sys.argv[1], np.array([tods[d] for d in range(len(fp))]))


if __name__ == "__main__":
    main()
