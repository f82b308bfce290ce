"""Beams that change with time from Python (docs/beams.md, "Beams that change with time"): a detector
with beam_sequence=[(time, beam), ...] gives, at each sample's time, the two nodes' TOD linearly
interpolated; the same TOD as the node beams convolved as fixed detectors and combined by hand, on a
scan across both poles with a monopole and a dipole in the sky; its adjoint is its transpose; bad
sequences and times are refused with the detector, node or sample named."""

import numpy as np
import pytest

import pisco
from pisco import deg


def sky(nside=32):
    """Random I, Q, U on a monopole and a dipole."""
    import healpy as hp

    rng = np.random.default_rng(4)
    npix = 12 * nside**2
    maps = rng.normal(size=(3, npix))
    x, y, z = hp.pix2vec(nside, np.arange(npix))
    maps[0] += 10.0 + 2.0 * z + 0.5 * x
    return pisco.Sky.from_maps(maps)


def scan(n=300):
    rng = np.random.default_rng(2)
    theta = np.arccos(rng.uniform(-1, 1, n))
    m = n // 8
    theta[:m] = rng.uniform(0, 5 * deg, m)  # across the north pole
    theta[m : 2 * m] = np.pi - rng.uniform(0, 5 * deg, m)  # and the south
    return theta, rng.uniform(0, 2 * np.pi, n), rng.uniform(-np.pi, np.pi, n)


def backends():
    """The float64 reference, and simd where it is compiled in."""
    available = {b.name for b in pisco.devices() if b.available}
    return ["cpu"] + (["simd"] if "simd" in available else [])


@pytest.mark.parametrize("backend", backends())
def test_the_sequence_is_its_nodes_interpolated(backend):
    beams = [pisco.Beamsor.elliptical_gaussian(2.0 * deg, 1.4 * deg, angle=0.2),
             pisco.Beamsor.elliptical_gaussian(2.5 * deg, 1.5 * deg, angle=1.1),
             pisco.Beamsor.gaussian(2.2 * deg)]
    fp = pisco.FocalPlane()
    fp.add("drift", zeta=0.3, beam_sequence=[(0.0, 0), (60.0, 1), (200.0, 2)])
    for k in range(3):
        fp.add(f"node{k}", zeta=0.3, beam=k)
    engine = pisco.Engine(sky(), beams, fp, backend=backend)
    theta, phi, psi = scan()
    time = np.linspace(0.0, 200.0, theta.size)
    tod = engine.convolve("drift", theta, phi, psi, time=time)
    nodes = [engine.convolve(f"node{k}", theta, phi, psi) for k in range(3)]
    k = np.where(time < 60.0, 0, 1)
    t0, t1 = np.array([0.0, 60.0])[k], np.array([60.0, 200.0])[k]
    w = (time - t0) / (t1 - t0)
    want = np.where(k == 0, (1 - w) * nodes[0] + w * nodes[1], (1 - w) * nodes[1] + w * nodes[2])
    assert np.max(np.abs(tod - want)) <= 1e-12 * np.sqrt(np.mean(want**2))
    # The adjoint: sum(s A^T d) == sum(A s d).
    d = np.random.default_rng(5).normal(size=tod.size)
    back = engine.adjoint("drift", d, theta, phi, psi, time=time)
    s = sky()
    maps = np.array([s.I, s.Q, s.U, s.V])
    forward, adjoint = float(tod @ d), float(np.sum(maps * back))
    assert abs(forward - adjoint) <= (1e-12 if backend == "cpu" else 1e-5) * np.linalg.norm(tod) * np.linalg.norm(d)
    assert abs(forward) > 1e-3 * np.linalg.norm(tod) * np.linalg.norm(d)


def test_bad_sequences_and_times_are_refused():
    beams = [pisco.Beamsor.gaussian(3 * deg), pisco.Beamsor.gaussian(4 * deg)]
    s = sky(16)
    fp = pisco.FocalPlane()
    fp.add("drift", beam_sequence=[(0.0, 0), (10.0, 1)])
    d = pisco.Detector("x", beam_sequence=[(0.0, 0), (5.0, 1)])
    assert d.beam_sequence == [(0.0, 0), (5.0, 1)]
    with pytest.raises(TypeError, match=r"beam_sequence\[1\]: expected a \(time, beam\) pair"):
        pisco.Detector("x", beam_sequence=[(0.0, 0), 5.0])
    with pytest.raises(TypeError, match=r"beam_sequence\[0\]: the beam must be an index"):
        pisco.Detector("x", beam_sequence=[(0.0, 0.5), (1.0, 1)])
    bad = pisco.FocalPlane()
    bad.add("drift", beam_sequence=[(5.0, 0), (1.0, 1)])
    with pytest.raises(pisco.Error, match="beam_sequence node 1: time = 1 s is not after node 0's 5 s"):
        pisco.Engine(s, beams, bad)
    engine = pisco.Engine(s, beams, fp)
    theta, phi, psi = scan(5)
    with pytest.raises(pisco.Error, match="has a beam that changes with time"):
        engine.convolve("drift", theta, phi, psi)
    with pytest.raises(ValueError, match="time: 4 samples, but the pointing has 5"):
        engine.convolve("drift", theta, phi, psi, time=np.zeros(4))
    with pytest.raises(pisco.Error, match=r"sample 2 is at time 11 s, outside its beam_sequence's nodes \(0 to 10 s\)"):
        engine.convolve("drift", theta, phi, psi, time=np.array([0.0, 1.0, 11.0, 2.0, 3.0]))


def trig_weights(x, n):
    """The weights of the n samples at 2 pi k / n in the trigonometric interpolant at x, from numpy's FFT:
    the interpolant of the k-th unit vector (the Nyquist term of an even n as its cosine)."""
    w = np.empty(n)
    for k in range(n):
        e = np.zeros(n)
        e[k] = 1.0
        c = np.fft.rfft(e) / n
        v = c[0].real
        for m in range(1, n // 2 + 1):
            f = 1.0 if (n % 2 == 0 and m == n // 2) else 2.0
            v += f * (c[m] * np.exp(1j * m * x)).real
        w[k] = v
    return w


@pytest.mark.parametrize("backend", backends())
def test_plate_beams_are_their_beams_interpolated_in_the_plate_angle(backend):
    """A beam that turns with the plate (pisco.PlateBeams): at each sample's hwp_angle, the beams'
    trigonometric interpolant, against the beams as fixed detectors combined by hand with weights from
    numpy's FFT, each beam's TOD scaled by its Omega~ over their mean."""
    n = 4
    beams = [pisco.Beamsor.elliptical_gaussian(2.0 * deg, (1.4 + 0.1 * k) * deg, angle=0.4 * k) for k in range(n)]
    fp = pisco.FocalPlane()
    fp.add("turning", zeta=0.2, plate_beams=pisco.PlateBeams(list(range(n)), gamma=0.3))
    for k in range(n):
        fp.add(f"beam{k}", zeta=0.2, beam=k)
    engine = pisco.Engine(sky(), beams, fp, backend=backend)
    theta, phi, psi = scan()
    h = np.random.default_rng(8).uniform(0, 2 * np.pi, theta.size)
    tod = engine.convolve("turning", theta, phi, psi, hwp_angle=h)
    each = np.array([engine.convolve(f"beam{k}", theta, phi, psi) for k in range(n)])
    omega = np.array([b.omega_tilde for b in beams])
    scale = omega / omega.mean()
    want = np.array([trig_weights(2 * np.pi * (h[i] - 0.3) / np.pi, n) @ (scale * each[:, i]) for i in range(h.size)])
    assert np.max(np.abs(tod - want)) <= 1e-12 * np.sqrt(np.mean(want**2))


def test_bad_plate_beams_are_refused():
    beams = [pisco.Beamsor.gaussian(3 * deg), pisco.Beamsor.gaussian(4 * deg)]
    s = sky(16)
    with pytest.raises(TypeError, match=r"beams\[1\]: expected a beam index"):
        pisco.PlateBeams([0, "b"])
    with pytest.raises(TypeError, match="plate_beams: expected a pisco.PlateBeams or None"):
        pisco.Detector("x", plate_beams=[0, 1])
    twice = pisco.FocalPlane()
    twice.add("x", plate_beams=pisco.PlateBeams([0, 1]), hwp=pisco.HalfWavePlate())
    with pytest.raises(pisco.Error, match="would count the plate twice"):
        pisco.Engine(s, beams, twice)
    fp = pisco.FocalPlane()
    fp.add("x", plate_beams=pisco.PlateBeams([0, 1]))
    engine = pisco.Engine(s, beams, fp)
    theta, phi, psi = scan(5)
    with pytest.raises(pisco.Error, match="has a half-wave plate: expected 5 plate angles"):
        engine.convolve("x", theta, phi, psi)
