"""Point sources, fixed and moving, from Python (pisco.SourceTrack, Engine.add_sources; docs/sources.md):
a source at a pixel's centre against that pixel in a plain pixel sum, a raster over a moving source whose
beam map is the truncated Gaussian's own, and the errors."""

import math

import numpy as np
import pytest

import pisco
from pisco import deg

hp = pytest.importorskip("healpy")


def test_a_source_at_a_pixel_centre_reads_as_that_pixel():
    nside = 64
    pixel = hp.ang2pix(nside, 1.1, 2.0)
    theta0, phi0 = hp.pix2ang(nside, pixel)
    area = hp.nside2pixarea(nside)
    maps = np.zeros((4, 12 * nside * nside))
    maps[:, pixel] = [2.0, 0.3, -0.5, 0.1]
    sky = pisco.Sky.from_maps(maps)
    fp = pisco.FocalPlane()
    det = pisco.Detector("d")
    det.zeta = 0.4
    fp.add(det)
    beam = pisco.Beamsor.elliptical_gaussian(1.0 * deg, 0.7 * deg, 0.3, rho_max=2.5 * deg)
    rng = np.random.default_rng(3)
    n = 400
    theta = theta0 + rng.uniform(-2.0, 2.0, n) * deg
    phi = phi0 + rng.uniform(-2.0, 2.0, n) * deg / math.sin(theta0)
    psi = rng.uniform(0, 2 * math.pi, n)
    source = pisco.SourceTrack.fixed("s", theta0, phi0, *(maps[:, pixel] * area))
    with pisco.Engine(sky, beam, fp, backend="cpu", quadrature="plain") as engine:
        from_map = engine.convolve(0, theta, phi, psi)
        from_source = engine.add_sources(0, np.zeros(n), [source], theta, phi, psi)
    assert np.abs(from_map).max() > 0
    assert np.abs(from_source - from_map).max() <= 1e-12 * np.abs(from_map).max()


def test_a_raster_over_a_moving_source_maps_the_beam():
    """Jupiter-like: a source moving 0.5 deg in 600 s and brightening by 20%; the boresight rasters
    across it on a grid of offsets from where it is at each sample's time; the TOD over the source's own
    flux is the beam, 0.5 F B(rho) / Omega~ for an ideal detector (docs/physics.md, "Normalization")."""
    fwhm, rho_max = 1.0 * deg, 2.5 * deg
    sigma = fwhm / math.sqrt(8 * math.log(2))
    track = pisco.SourceTrack("jupiter", [0.0, 600.0], [1.2, 1.2 + 0.3 * deg], [0.5, 0.5 + 0.4 * deg], [2e-4, 2.4e-4])
    x, y = np.meshgrid(np.linspace(-2.0, 2.0, 21) * deg, np.linspace(-2.0, 2.0, 21) * deg)
    x, y = x.ravel(), y.ravel()
    t = np.linspace(0.0, 600.0, x.size)
    # Where the source is at each time (the great circle at a constant rate, written out here).
    a, b = hp.ang2vec(1.2, 0.5), hp.ang2vec(1.2 + 0.3 * deg, 0.5 + 0.4 * deg)
    omega = math.acos(np.dot(a, b))
    u = t / 600.0
    k = (np.sin((1 - u) * omega)[:, None] * a + np.sin(u * omega)[:, None] * b) / math.sin(omega)
    ks_theta, ks_phi = hp.vec2ang(k)
    flux = 2e-4 + u * 0.4e-4
    # The boresight at offset (x, y) from the source in its local (theta, phi) frame, exactly.
    e_theta = np.stack([np.cos(ks_theta) * np.cos(ks_phi), np.cos(ks_theta) * np.sin(ks_phi), -np.sin(ks_theta)], 1)
    e_phi = np.stack([-np.sin(ks_phi), np.cos(ks_phi), np.zeros_like(ks_phi)], 1)
    rho = np.hypot(x, y)
    direction = (x[:, None] * e_theta + y[:, None] * e_phi) / np.maximum(rho, 1e-300)[:, None]
    v = np.cos(rho)[:, None] * k + np.sin(rho)[:, None] * direction
    theta, phi = hp.vec2ang(v)
    fp = pisco.FocalPlane()
    fp.add("d")
    beam = pisco.Beamsor.gaussian(fwhm, rho_max=rho_max)
    with pisco.Engine(pisco.Sky(64), beam, fp, backend="simd") as engine:
        tod = engine.add_sources(0, t, [track], theta, phi, np.zeros(x.size))
    r = np.linspace(0, rho_max, 20001)
    omega_tilde = np.trapezoid(2 * math.pi * np.sin(r) * np.exp(-r**2 / (2 * sigma**2)), r)
    beam_map = tod / (0.5 * flux / omega_tilde)
    want = np.where(rho <= rho_max, np.exp(-rho**2 / (2 * sigma**2)), 0.0)
    assert np.abs(beam_map - want).max() < 2e-6


def test_bad_sources_and_calls_are_refused():
    with pytest.raises(pisco.Error, match="source 'mars', point 1: the time 1 does not follow 1"):
        pisco.SourceTrack("mars", [1.0, 1.0], [1.0, 1.1], [2.0, 2.1], [1.0, 1.0])
    with pytest.raises(pisco.Error, match="theta is 4"):
        pisco.SourceTrack.fixed("far", 4.0, 0.0, 1.0)
    fp = pisco.FocalPlane()
    fp.add("d")
    beam = pisco.Beamsor.gaussian(1.0 * deg, rho_max=2.5 * deg)
    track = pisco.SourceTrack("moon", [0.0, 10.0], [1.0, 1.01], [2.0, 2.01], [1.0, 1.0])
    with pisco.Engine(pisco.Sky(64), beam, fp, backend="cpu") as engine:
        with pytest.raises(pisco.Error, match="detector 'd': source 'moon': sample 1 is at time 20"):
            engine.add_sources(0, np.array([0.0, 20.0]), [track], np.ones(2), np.full(2, 2.0), np.zeros(2))
        with pytest.raises(ValueError, match="time has 3 samples"):
            engine.add_sources(0, np.zeros(3), [track], np.ones(2), np.full(2, 2.0), np.zeros(2))
    with pisco.Engine(pisco.Sky(64), beam, fp, backend="cpu", normalization="per_sample") as engine:
        with pytest.raises(pisco.Error, match="integral normalization"):
            engine.add_sources(0, np.zeros(1), [track], np.ones(1), np.full(1, 2.0), np.zeros(1))
