"""The package's API: skies, beams, focal planes, the engine, arrays and errors, threads, stubs."""

import ast
import gc
import os
import re
import subprocess
import sys
import textwrap
import threading
import time

import numpy as np
import pytest

import pisco
from pisco import deg


def small_setup(nside=32, fwhm=2 * deg, seed=1):
    rng = np.random.default_rng(seed)
    maps = rng.normal(size=(3, 12 * nside * nside))
    sky = pisco.Sky.from_maps(maps, units="uK_CMB")
    beam = pisco.Beamsor.gaussian(fwhm, rho_max=2.5 * fwhm)
    fp = pisco.FocalPlane()
    fp.add_pair("p", zeta=0.3)
    fp.add("off", zeta=0.1, epsilon=0.05, gain=1.2, offset=pisco.offset_quat(1 * deg, -0.5 * deg, 0.2))
    return sky, beam, fp


def pointing(n, seed=2):
    rng = np.random.default_rng(seed)
    theta = np.arccos(rng.uniform(-1, 1, n))
    phi = rng.uniform(0, 2 * np.pi, n)
    psi = rng.uniform(-np.pi, np.pi, n)
    return theta, phi, psi


# --- the sky -------------------------------------------------------------------------------------


def test_sky_views_are_the_sky_storage():
    sky = pisco.Sky(4, units="K")
    assert (sky.nside, sky.npix, sky.units) == (4, 192, "K")
    view = sky.Q
    view[5] = 2.5
    assert sky.Q[5] == 2.5 and view.flags.writeable and view.dtype == np.float64
    del sky  # the view keeps the sky alive
    assert view[5] == 2.5
    assert np.isclose(pisco.Sky(8).pixel_area, 4 * np.pi / 768)


def test_sky_from_maps_and_fits(tmp_out):
    maps = np.arange(3 * 48, dtype=np.float64).reshape(3, 48)
    sky = pisco.Sky.from_maps(maps)
    assert sky.nside == 2 and np.array_equal(sky.U, maps[2]) and not np.any(sky.V)
    sky4 = pisco.Sky.from_maps([maps[0], maps[1], maps[2], maps[0]])
    assert np.array_equal(sky4.V, maps[0])
    assert np.array_equal(pisco.Sky.from_maps(maps[0]).I, maps[0])
    path = tmp_out / "sky.fits"
    sky.write_fits(path)
    back = pisco.Sky.read_fits(str(path))
    assert np.array_equal(back.Q, sky.Q)


@pytest.mark.parametrize("nside", [0, 3, 12, 16384])
def test_sky_nside_must_be_a_power_of_two(nside):
    with pytest.raises(ValueError, match="nside: NSIDE = .* power of two"):
        pisco.Sky(nside)


def test_sky_from_maps_errors():
    with pytest.raises(ValueError, match="not 12 NSIDE"):
        pisco.Sky.from_maps(np.zeros((3, 100)))
    with pytest.raises(ValueError, match="12 NSIDE"):
        pisco.Sky.from_maps(np.zeros((3, 12 * 12 * 12)))  # NSIDE 12
    with pytest.raises(TypeError, match=r"maps\[0\]: expected float64 .* int64"):
        pisco.Sky.from_maps(np.zeros((3, 48), dtype=np.int64))
    with pytest.raises(ValueError, match=r"expected 1 \(I\), 3"):
        pisco.Sky.from_maps(np.zeros((2, 48)))
    bad = np.zeros((3, 48))
    bad[1, 7] = np.nan
    with pytest.raises(ValueError, match=r"maps\[1\]\[7\] is nan"):
        pisco.Sky.from_maps(bad)
    with pytest.raises(ValueError, match="not C-contiguous"):
        pisco.Sky.from_maps(np.zeros((48, 3)).T)
    with pytest.raises(pisco.Error, match="nothere.fits"):
        pisco.Sky.read_fits("nothere.fits")


# --- beams and focal planes ----------------------------------------------------------------------


def test_beamsor_builders(tmp_out):
    g = pisco.Beamsor.gaussian(1 * deg, rho_max=3 * deg)
    assert g.is_radial and np.isclose(g.rho_max, 3 * deg)
    # The integral of a Gaussian of FWHM f over the sphere: 2 pi s^2, s = f / sqrt(8 ln 2).
    s = 1 * deg / np.sqrt(8 * np.log(2))
    assert np.isclose(g.omega_tilde, 2 * np.pi * s**2, rtol=1e-3)
    tt = g.element(0, 0)
    assert tt is not None and not tt.flags.writeable and g.element(0, 3) is None
    assert g.at(0.0, 0.0).shape == (4, 4) and g.at(0.0, 0.0)[0, 0] == pytest.approx(1.0)
    e = pisco.Beamsor.elliptical_gaussian(1 * deg, 0.5 * deg, 0.3, rho_max=3 * deg, cross_polar=0.01)
    assert not e.is_radial
    f = pisco.Beamsor.from_field(lambda rho, sigma: np.diag([np.exp(-rho**2 / 2 / s**2)] * 2 + [0.0, 0.0]),
                                 3 * deg, 0.05 * deg, "field")
    assert f.omega_tilde == pytest.approx(g.omega_tilde, rel=2e-3)
    path = tmp_out / "beam.fits"
    g.write_fits(str(path), 256)
    r = pisco.Beamsor.read_fits(str(path), 3 * deg)
    assert r.omega_tilde == pytest.approx(g.omega_tilde, rel=3e-2)  # a pixel sum at NSIDE 256
    with pytest.raises(ValueError, match="cross_polar_pattern"):
        pisco.Beamsor.gaussian(1 * deg, cross_polar_pattern="octupole")
    with pytest.raises(pisco.Error):
        pisco.Beamsor.gaussian(1 * deg, rho_max=100 * deg)


def test_focal_plane_builders():
    fp = pisco.FocalPlane()
    assert fp.add("a", zeta=0.1, epsilon=0.02, gain=1.1, beam=0) == 0
    assert fp.add_pair("p", zeta=0.2) == 1
    d = pisco.Detector("x", zeta=0.4)
    d.set_offset(1 * deg, 2 * deg, 0.3)
    fp.add(d)
    assert fp.names == ["a", "pa", "pb", "x"] and len(fp) == 4
    assert fp["pb"].zeta == pytest.approx(0.2 - np.pi / 2)
    assert fp[-1].offset_xi_eta_gamma() == pytest.approx((1 * deg, 2 * deg, 0.3))
    with pytest.raises(KeyError):
        fp["nobody"]
    with pytest.raises(TypeError, match="index or name"):
        fp[1.5]
    with pytest.raises(TypeError, match="a pisco.Detector or a name"):
        fp.add(3)
    with pytest.raises(IndexError):
        fp[4]
    cols = pisco.FocalPlane.from_columns(
        {"name": ["a", "b"], "zeta": [0.0, 0.5], "epsilon": [0.0, 0.1], "xi": [0.0, 1 * deg], "eta": [0, 0],
         "gamma": [0, 0], "beam": [0, 1]})
    assert cols["b"].beam == 1 and cols["b"].offset_xi_eta_gamma()[0] == pytest.approx(1 * deg)
    from astropy import units as u
    from astropy.table import QTable

    table = QTable({"name": ["a", "b"], "zeta": [0.0, 30.0] * u.deg, "quat": [[0, 0, 0, 1.0], [0, 0, 0.6, 0.8]]})
    t = pisco.FocalPlane.from_columns(table)
    assert t["b"].zeta == pytest.approx(np.radians(30)) and t["b"].offset == pytest.approx([0, 0, 0.6, 0.8])


# --- the engine ----------------------------------------------------------------------------------


def test_engine_convolves_angles_and_quaternions_alike():
    sky, beam, fp = small_setup()
    theta, phi, psi = pointing(500)
    quats = np.array([pisco.quat_from_pointing(t, p, s) for t, p, s in zip(theta, phi, psi)])
    with pisco.Engine(sky, beam, fp, backend="cpu") as engine:
        assert engine.backend == "cpu" and len(engine) == 3 and engine.focal_plane.names == fp.names
        for det in range(3):
            a = engine.convolve(det, theta, phi, psi)
            b = engine.convolve(fp.names[det], boresight_quats=quats)
            assert a.dtype == np.float64 and a.shape == (500,)
            assert np.max(np.abs(a - b)) <= 1e-12 * np.max(np.abs(a))
        assert engine.mean_disc_pixels > 10
    assert engine.closed


def test_adjoint_is_the_transpose_of_convolve():
    # <s, A^T d> = <A s, d> from Python, with a monopole and dipole on the sky, samples at the poles,
    # angles and quaternions; out accumulates; set_sky gives a new sky's TOD.
    sky, beam, fp = small_setup(nside=16, fwhm=4 * deg)
    nside = 16
    maps = np.array([sky.I, sky.Q, sky.U]) + 0.0
    maps[0] += 2.725 + 3e-3 * np.cos(np.linspace(0, np.pi, maps.shape[1]))
    sky = pisco.Sky.from_maps(maps, units="uK_CMB")
    theta, phi, psi = pointing(400)
    theta[:20] = np.linspace(0, 0.02, 20)
    quats = np.array([pisco.quat_from_pointing(t, p, s) for t, p, s in zip(theta, phi, psi)])
    rng = np.random.default_rng(5)
    for backend in [b.name for b in pisco.devices() if b.available and b.capabilities["adjoint"]]:
        with pisco.Engine(sky, beam, fp, backend=backend) as engine:
            assert engine.npix == 12 * nside * nside
            forward = back = 0.0
            out = np.zeros((4, engine.npix))
            for det in range(len(fp)):
                d = rng.normal(size=400)
                tod = engine.convolve(det, theta, phi, psi)
                forward += tod @ d
                engine.adjoint(det, d, boresight_quats=quats, out=out)
            back = sum(np.asarray(m) @ out[k] for k, m in enumerate([sky.I, sky.Q, sky.U, sky.V]))
            bar = 1e-12 if backend == "cpu" else 1e-5
            assert abs(forward - back) <= bar * abs(forward), (backend, forward, back)
            single = engine.adjoint(0, d, theta, phi, psi)
            assert single.shape == (4, engine.npix) and np.any(single[0] != 0)
            diag = engine.adjoint_diagonal(0, theta, phi, psi)
            assert np.all(diag >= 0) and np.any(diag[0] > 0)
            with pytest.raises(ValueError, match="out must have shape"):
                engine.adjoint(0, d, theta, phi, psi, out=np.zeros((3, engine.npix)))
            with pytest.raises(ValueError, match="tod has 3 samples"):
                engine.adjoint(0, d[:3], theta, phi, psi)
            other = pisco.Sky.from_maps(maps * 0.5, units="uK_CMB")
            engine.set_sky(other)
            with pisco.Engine(other, beam, fp, backend=backend) as fresh:
                fresh.prepare()  # the polar copy made at set-up: the same TOD as made by the first submission
                assert np.array_equal(engine.convolve(1, theta, phi, psi), fresh.convolve(1, theta, phi, psi))


def test_normal_is_the_adjoint_of_the_convolution():
    # engine.normal(...) = engine.adjoint(convolve(...)) of the engine's sky, with samples at the poles
    # and a plate; on simd without a monopole on the sky (one pass over each disc) and with one (its
    # float64 path: two passes), and on the reference; angles and quaternions; out accumulates.
    sky, beam, fp = small_setup(nside=16, fwhm=4 * deg)
    fp.add("plated", zeta=0.2, hwp=pisco.HalfWavePlate(gamma=0.1))
    theta, phi, psi = pointing(300)
    theta[:15] = np.linspace(0, 0.02, 15)
    h = np.arange(300) * 0.3
    quats = np.array([pisco.quat_from_pointing(t, p, s) for t, p, s in zip(theta, phi, psi)])
    base = np.array([sky.I, sky.Q, sky.U]) + 0.0
    for monopole in [0.0, 2.725]:
        maps = base.copy()
        maps[0] += monopole + 3e-3 * np.cos(np.linspace(0, np.pi, maps.shape[1]))
        s = pisco.Sky.from_maps(maps, units="uK_CMB")
        for backend in [b.name for b in pisco.devices() if b.available and b.capabilities["adjoint"]]:
            with pisco.Engine(s, beam, fp, backend=backend) as engine:
                for det in range(len(fp)):
                    hw = h if det == len(fp) - 1 else None
                    tod = engine.convolve(det, theta, phi, psi, hwp_angle=hw)
                    two = engine.adjoint(det, tod, theta, phi, psi, hwp_angle=hw)
                    one = engine.normal(det, boresight_quats=quats, hwp_angle=hw)
                    assert np.any(two[0] != 0)
                    assert np.abs(one - two).max() <= 1e-5 * np.abs(two).max(), (backend, monopole, det)
                    out = one.copy()
                    engine.normal(det, boresight_quats=quats, hwp_angle=hw, out=out)
                    # (the main and polar parts are added into out one after the other)
                    assert np.abs(out - 2 * one).max() <= 1e-12 * np.abs(one).max()
    with pisco.Engine(s, beam, fp, backend="cpu") as engine:
        with pytest.raises(ValueError, match="different lengths"):
            engine.normal(0, theta[:3], phi, psi)
        with pytest.raises(pisco.Error, match="hwp_angle"):
            engine.normal(len(fp) - 1, theta, phi, psi)


def test_deconvolving_mapmaker_recovers_a_mismatched_pair():
    # A pair with mismatched elliptical beams and offsets over the whole sphere: the deconvolving
    # map-maker's solution, reconvolved, against the sky smoothed the same way, and its progress.
    healpy = pytest.importorskip("healpy")
    nside = 8
    rng = np.random.default_rng(3)
    lmax = 2 * nside
    cl = np.zeros(lmax + 1)
    cl[2:] = 1.0 / np.arange(2, lmax + 1) ** 2
    maps = np.array(healpy.synfast([cl, 0.1 * cl, 0.03 * cl, 0 * cl], nside, new=True, lmax=lmax, pol=True))
    sky = pisco.Sky.from_maps(maps, units="uK_CMB")
    fp = pisco.FocalPlane()
    fp.add("a", zeta=0.3, beam=0, offset=pisco.offset_quat(0.5 * deg, 0.0, 0.0))
    fp.add("b", zeta=0.3 - np.pi / 2, beam=1, offset=pisco.offset_quat(0.52 * deg, 0.03 * deg, 0.0))
    beams = [pisco.Beamsor.elliptical_gaussian(14 * deg, 12 * deg, 0.3, rho_max=25 * deg),
             pisco.Beamsor.elliptical_gaussian(13 * deg, 12.5 * deg, -0.5, rho_max=25 * deg)]
    theta, phi, psi = pointing(6000, seed=4)
    backends = [b.name for b in pisco.devices() if b.available and b.capabilities["adjoint"]]
    with pisco.Engine(sky, beams, fp, backend="simd" if "simd" in backends else "cpu", quadrature="plain") as engine:
        maker = pisco.DeconvolvingMapmaker(engine, max_iterations=40, tolerance=1e-9, target_fwhm=15 * deg)
        chunks = [dict(detector=d, theta=theta[k:k + 2000], phi=phi[k:k + 2000], psi=psi[k:k + 2000])
                  for d in range(2) for k in range(0, 6000, 2000)]
        for c in chunks:
            maker.add(c["detector"], engine.convolve(c["detector"], c["theta"], c["phi"], c["psi"]),
                      c["theta"], c["phi"], c["psi"])
        seen = []
        with pytest.warns(RuntimeWarning, match="did not converge"):  # a tolerance of 1e-9 in 40 iterations
            result = maker.solve(lambda: iter(chunks), progress=lambda it, res, sec: seen.append((it, res)))
    assert result["iterations"] == len(seen) and seen[0][0] == 1
    assert result["residuals"][-1] < 1e-2 * result["residuals"][0]
    want = healpy.smoothing(maps, fwhm=15 * deg, iter=3, lmax=3 * nside - 1, use_pixel_weights=False)
    got = np.array([result["smoothed_I"], result["smoothed_Q"], result["smoothed_U"]])
    for k in range(3):
        err = np.sqrt(np.mean((got[k] - want[k]) ** 2) / np.mean(want[k] ** 2))
        assert err < 0.05, ("IQU"[k], err)
    with pisco.Engine(sky, beams, fp, backend="cpu") as engine:
        maker = pisco.DeconvolvingMapmaker(engine)
        with pytest.raises(pisco.InputError, match="no TOD was added"):
            maker.solve(lambda: iter(chunks))
        c = chunks[0]
        maker.add(0, np.ones(2000), c["theta"], c["phi"], c["psi"])
        with pytest.raises(TypeError, match="must yield dicts"):
            maker.solve(lambda: [1])
        with pytest.raises(ValueError, match="tod has 3 samples"):
            maker.add(0, np.ones(3), c["theta"], c["phi"], c["psi"])
        with pytest.raises(ValueError, match="regularize = 'polarisation'; expected 'all' or 'polarization'"):
            pisco.DeconvolvingMapmaker(engine, regularize="polarisation")
        assert pisco.DeconvolvingMapmaker(engine, regularization=1e-3, regularize="polarization") is not None


def test_deconvolving_mapmaker_warns_and_leaves_out_what_the_data_do_not_constrain():
    """One angle per pixel: Q and U left out (unseen), said in left_out, and a RuntimeWarning; a solve
    that stops short of its tolerance warns too."""
    healpy = pytest.importorskip("healpy")
    nside = 8
    sky = pisco.Sky(nside)
    sky.I[:] = 1.0
    sky.Q[:] = 0.1
    beam = pisco.Beamsor.gaussian(15 * deg, rho_max=30 * deg)
    fp = pisco.FocalPlane()
    fp.add_pair("p", zeta=0.0, beam_a=0, beam_b=0)
    theta, phi = healpy.pix2ang(nside, np.arange(12 * nside**2))
    psi = np.zeros_like(theta)
    with pisco.Engine(sky, beam, fp, backend="cpu") as engine:
        maker = pisco.DeconvolvingMapmaker(engine, max_iterations=3)
        for d in range(2):
            maker.add(d, engine.convolve(d, theta, phi, psi), theta, phi, psi)
        chunks = [dict(detector=d, theta=theta, phi=phi, psi=psi) for d in range(2)]
        with pytest.warns(RuntimeWarning) as caught:
            result = maker.solve(lambda: iter(chunks))
    messages = [str(w.message) for w in caught]
    assert any("constrain Q and U in no pixel" in m for m in messages), messages
    assert any("did not converge" in m for m in messages), messages
    assert result["polarization_unconstrained"] is True and result["polarization_pixels"] == 0
    assert np.all(result["Q"] == healpy.UNSEEN) and np.all(result["U"] == healpy.UNSEEN)
    assert np.all(result["I"] != healpy.UNSEEN)
    assert any(line.startswith("Q and U everywhere") for line in result["left_out"])


def test_deconvolving_mapmaker_after_its_engine_is_closed():
    """A DeconvolvingMapmaker whose engine was closed raises ValueError on every call (it never reads
    freed memory); a survey that calls the engine the solve is running on raises instead of waiting
    for itself."""
    sky, beam, fp = small_setup()
    theta, phi, psi = pointing(50)
    engine = pisco.Engine(sky, beam, fp, backend="cpu")
    maker = pisco.DeconvolvingMapmaker(engine, max_iterations=2)
    tod = engine.convolve(0, theta, phi, psi)
    maker.add(0, tod, theta, phi, psi)
    chunks = [dict(detector=0, theta=theta, phi=phi, psi=psi)]

    def survey_calling_the_engine():
        engine.convolve(0, theta, phi, psi)
        return iter(chunks)

    with pytest.raises(ValueError, match="used by the survey of a DeconvolvingMapmaker.solve"):
        maker.solve(survey_calling_the_engine)
    assert len(maker.solve(lambda: iter(chunks))["I"]) == 12 * sky.nside**2  # the engine is usable again
    engine.close()
    with pytest.raises(ValueError, match=r"DeconvolvingMapmaker.add: its engine was closed \(Engine.close\(\)\)"):
        maker.add(0, tod, theta, phi, psi)
    with pytest.raises(ValueError, match=r"DeconvolvingMapmaker.solve: its engine was closed"):
        maker.solve(lambda: iter(chunks))
    with pytest.raises(ValueError, match="used after close"):
        pisco.DeconvolvingMapmaker(engine)
    del engine  # the maker keeps the closed engine object alive; still no crash
    gc.collect()
    with pytest.raises(ValueError, match="its engine was closed"):
        maker.add(0, tod, theta, phi, psi)


def test_out_is_written_in_place_and_accumulates():
    sky, beam, fp = small_setup()
    theta, phi, psi = pointing(300)
    engine = pisco.Engine(sky, [beam], fp, backend="cpu")
    ref = engine.convolve(0, theta, phi, psi)
    out = np.full(300, np.nan)
    assert engine.convolve(0, theta, phi, psi, out=out) is out
    assert np.array_equal(out, ref)
    acc = np.ones(300)
    engine.convolve(0, theta, phi, psi, out=acc, accumulate=True)
    assert np.array_equal(acc, ref + 1.0)
    # A row of a detector-data matrix, as TOAST and litebird_sim hold TOD.
    tods = np.zeros((3, 300))
    engine.convolve(2, theta, phi, psi, out=tods[2])
    assert np.array_equal(tods[2], engine.convolve(2, theta, phi, psi)) and not np.any(tods[:2])


def test_submit_and_wait_give_convolve():
    sky, beam, fp = small_setup()
    theta, phi, psi = pointing(1000)
    engine = pisco.Engine(sky, beam, fp, backend="cpu")
    ref = [engine.convolve(d, theta, phi, psi) for d in range(3)]
    outs = [np.zeros(1000) for _ in range(3)]
    tickets = [engine.submit(d, theta, phi, psi, out=outs[d]) for d in range(3)]
    engine.wait(tickets[1])
    assert np.array_equal(outs[0], ref[0]) and np.array_equal(outs[1], ref[1])
    engine.wait()
    assert np.array_equal(outs[2], ref[2])
    with pytest.raises(TypeError, match="out is required"):
        engine.submit(0, theta, phi, psi)
    # An engine dropped with submissions in flight completes them first: the arrays stay valid.
    late = np.zeros(1000)
    engine.submit(0, theta, phi, psi, out=late)
    del engine
    assert np.array_equal(late, ref[0])


def test_convolve_detectors_gives_each_detectors_convolve():
    sky, beam, fp = small_setup()
    fp.add("plated", zeta=0.2, hwp=pisco.HalfWavePlate(gamma=0.1),
           offset=pisco.offset_quat(-2 * deg, 1 * deg, 0.3))
    theta, phi, psi = pointing(700)
    theta[:5] = [0.0, 1e-3, np.pi, np.pi - 2e-3, 0.02]  # at and near both poles
    hwp = np.linspace(0.0, 40.0, 700)
    quats = np.array([pisco.quat_from_pointing(t, f, s) for t, f, s in zip(theta, phi, psi)])
    for backend in ("cpu", "simd"):
        engine = pisco.Engine(sky, beam, fp, backend=backend)
        names = ["pa", 3, "off", "pb"]
        ref = [engine.convolve(d, theta, phi, psi, hwp_angle=hwp if d == 3 else None) for d in names]
        got = engine.convolve_detectors(names, theta, phi, psi, hwp_angle=hwp)
        assert len(got) == 4 and all(np.array_equal(a, b) for a, b in zip(ref, got))
        rows = np.ones((4, 700))  # rows of a 2-D array, added into
        engine.convolve_detectors(names, boresight_quats=quats, out=rows, accumulate=True, hwp_angle=hwp)
        ref_q = [engine.convolve(d, boresight_quats=quats, hwp_angle=hwp if d == 3 else None) for d in names]
        assert all(np.array_equal(rows[k], 1.0 + ref_q[k]) for k in range(4))
    engine = pisco.Engine(sky, beam, fp, backend="cpu")
    assert engine.staged_samples == 0  # the host backends read the caller's pointing where it lies
    by_array = engine.convolve_detectors(np.array([2, 0]), theta, phi, psi)  # numpy integers
    assert np.array_equal(by_array[0], engine.convolve(2, theta, phi, psi))
    assert engine.convolve_detectors([], theta, phi, psi) == []
    if "vulkan" in [b.name for b in pisco.devices() if b.available]:
        # Away from the poles, the four detectors' pointing is staged once in each of the two slots.
        belt = 1.0 + theta / np.pi
        dev = pisco.Engine(sky, beam, fp, backend="vulkan")
        got = dev.convolve_detectors(names, belt, phi, psi, hwp_angle=hwp)
        assert dev.staged_samples == 2 * 700
        ref = engine.convolve_detectors(names, belt, phi, psi, hwp_angle=hwp)
        assert all(np.allclose(a, b, rtol=0, atol=1e-4 * np.std(b)) for a, b in zip(got, ref))
    with pytest.raises(TypeError, match="a sequence of indices or names, not one name"):
        engine.convolve_detectors("pa", theta, phi, psi)
    with pytest.raises(ValueError, match="out holds 1 arrays for 2 detectors"):
        engine.convolve_detectors([0, 1], theta, phi, psi, out=[np.zeros(700)])
    with pytest.raises(ValueError, match="out: 699 samples, but the pointing has 700"):
        engine.convolve_detectors([0, 1], theta, phi, psi, out=[np.zeros(700), np.zeros(699)])
    with pytest.raises(TypeError, match="accumulate=True adds into `out`"):
        engine.convolve_detectors([0], theta, phi, psi, accumulate=True)
    with pytest.raises(IndexError, match="index 9 but the focal plane has 4 detectors"):
        engine.convolve_detectors([0, 9], theta, phi, psi)
    with pytest.raises(ValueError, match=r"theta\[2\] is nan"):
        engine.convolve_detectors([0, 1], np.where(np.arange(700) == 2, np.nan, theta), phi, psi)
    # An error of a later detector (no plate angles for the plated one) after the first is queued:
    # the first completes into its array before the error is raised.
    first = np.zeros(700)
    with pytest.raises(ValueError, match="has a half-wave plate"):
        engine.convolve_detectors([0, 3], theta, phi, psi, out=[first, np.zeros(700)])
    assert np.array_equal(first, engine.convolve(0, theta, phi, psi))


def test_argument_errors_name_the_argument():
    sky, beam, fp = small_setup()
    theta, phi, psi = pointing(20)
    engine = pisco.Engine(sky, beam, fp, backend="cpu")
    cases = [
        (TypeError, r"theta: expected float64 values, got a float32", dict(theta=theta.astype(np.float32))),
        (TypeError, r"phi: expected a numpy array of float64, got list", dict(phi=list(phi))),
        (ValueError, r"psi: expected shape \(n,\)", dict(psi=np.zeros((20, 1)))),
        (ValueError, r"theta: the array is not C-contiguous", dict(theta=np.repeat(theta, 2)[::2])),
        (ValueError, r"theta\[3\] is nan", dict(theta=np.where(np.arange(20) == 3, np.nan, theta))),
        (ValueError, r"phi\[0\] is inf", dict(phi=np.where(np.arange(20) == 0, np.inf, phi))),
        (ValueError, r"theta\[1\] = 4 is outside \[0, pi\]", dict(theta=np.where(np.arange(20) == 1, 4.0, theta))),
        (ValueError, r"different lengths", dict(psi=psi[:10])),
    ]
    for error, message, change in cases:
        args = dict(theta=theta, phi=phi, psi=psi)
        args.update(change)
        with pytest.raises(error, match=message):
            engine.convolve(0, **args)
    quats = np.tile([0.0, 0.0, 0.0, 1.0], (20, 1))
    with pytest.raises(ValueError, match=r"boresight_quats: expected shape \(n, 4\)"):
        engine.convolve(0, boresight_quats=quats[:, :3].copy())
    with pytest.raises(ValueError, match=r"boresight_quats\[2\] has norm 2"):
        engine.convolve(0, boresight_quats=np.where(np.arange(20)[:, None] == 2, 2 * quats, quats))
    with pytest.raises(ValueError, match=r"boresight_quats\[3\] has norm 9.99999999999999\d*e\+199"):  # finite: not "non-finite"
        engine.convolve(0, boresight_quats=np.where(np.arange(20)[:, None] == 3, 1e200 * quats, quats))
    with pytest.raises(TypeError, match="either theta, phi and psi .* or boresight_quats"):
        engine.convolve(0, theta, phi, psi, boresight_quats=quats)
    with pytest.raises(TypeError, match="either"):
        engine.convolve(0)
    read_only = np.zeros(20)
    read_only.flags.writeable = False
    with pytest.raises(ValueError, match="out: the array is read-only"):
        engine.convolve(0, theta, phi, psi, out=read_only)
    with pytest.raises(ValueError, match="out: 19 samples, but the pointing has 20"):
        engine.convolve(0, theta, phi, psi, out=np.zeros(19))
    with pytest.raises(ValueError, match="out: the array is not C-contiguous"):
        engine.convolve(0, theta, phi, psi, out=np.zeros((20, 2))[:, 0])
    with pytest.raises(TypeError, match="out: expected float64"):
        engine.convolve(0, theta, phi, psi, out=np.zeros(20, dtype=np.float32))
    with pytest.raises(TypeError, match="accumulate=True adds into `out`"):
        engine.convolve(0, theta, phi, psi, accumulate=True)
    with pytest.raises(IndexError, match="index 3 but the focal plane has 3"):
        engine.convolve(3, theta, phi, psi)
    with pytest.raises(KeyError, match="no detector named 'q'"):
        engine.convolve("q", theta, phi, psi)


def test_engine_errors_and_close():
    sky, beam, fp = small_setup()
    with pytest.raises(pisco.InputError, match="backend 'nope' is unknown") as info:
        pisco.Engine(sky, beam, fp, backend="nope")
    assert isinstance(info.value, pisco.Error) and info.value.kind == "input"
    # Each kind of pisco::Error is its own subclass of pisco.Error (docs/python.md, "Errors").
    for info_ in pisco.devices():
        if not info_.available:
            with pytest.raises(pisco.UnavailableError) as unavailable:
                pisco.Engine(sky, beam, fp, backend=info_.name)
            assert unavailable.value.kind == "unavailable"
    with pytest.raises(pisco.FileError) as unwritable:
        sky.write_fits("/proc/no-such-directory/sky.fits")
    assert unwritable.value.kind == "io" and "sky.fits" in str(unwritable.value)
    assert {e.kind for e in (pisco.InputError, pisco.UnavailableError, pisco.DeviceError, pisco.FileError,
                             pisco.InternalError)} == {"input", "unavailable", "device", "io", "internal"}
    # Backends say what they can do (BackendCapabilities).
    caps = {b.name: b.capabilities for b in pisco.devices() if b.available}
    assert caps["cpu"]["float64"] and caps["cpu"]["worker_threads"] and caps["cpu"]["device_memory"] == 0
    assert all(c["plates"] for c in caps.values())
    assert all(c["adjoint"] for name, c in caps.items() if name != "vulkan")  # vulkan: with int64 atomics
    assert all(c["normal"] == (name == "simd") for name, c in caps.items())  # the one-pass normal
    with pytest.raises(TypeError, match="beams: expected a pisco.Beamsor"):
        pisco.Engine(sky, [beam, "beam"], fp, backend="cpu")
    bad = pisco.FocalPlane()
    bad.add("a", beam=3)
    with pytest.raises(pisco.Error) as info:
        pisco.Engine(sky, beam, bad, backend="cpu")
    assert isinstance(info.value, RuntimeError) and "beam" in str(info.value)
    engine = pisco.Engine(sky, beam, fp, backend="cpu")
    engine.close()
    engine.close()  # twice is fine
    theta, phi, psi = pointing(5)
    for call in (lambda: engine.convolve(0, theta, phi, psi), lambda: engine.wait(), lambda: engine.backend,
                 lambda: engine.submit(0, theta, phi, psi, out=np.zeros(5))):
        with pytest.raises(ValueError, match="used after close"):
            call()
    assert repr(engine) == "pisco.Engine(closed)"


def test_gil_is_released_and_engines_run_in_threads():
    """Two engines in two threads give the TOD of sequential runs, and Python runs meanwhile."""
    sky, beam, fp = small_setup(nside=64, fwhm=3 * deg)
    theta, phi, psi = pointing(60000)
    engines = [pisco.Engine(sky, beam, fp, backend="cpu", threads=1) for _ in range(2)]
    sequential = [engines[k].convolve(k, theta, phi, psi) for k in range(2)]
    results = [np.zeros(60000), np.zeros(60000)]
    start = threading.Barrier(3)

    def run(k):
        start.wait()
        engines[k].convolve(k, theta, phi, psi, out=results[k])

    threads = [threading.Thread(target=run, args=(k,)) for k in range(2)]
    for t in threads:
        t.start()
    start.wait()
    ticks = 0
    t0 = time.perf_counter()
    while any(t.is_alive() for t in threads):
        ticks += 1
    elapsed = time.perf_counter() - t0
    for t in threads:
        t.join()
    for k in range(2):
        assert np.array_equal(results[k], sequential[k])
    # With the GIL held by the engines this loop could only run between their calls: a switch interval
    # (5 ms, under 10,000 ticks) at most before each. Released, it runs throughout their 0.2 to 1 s of
    # work: hundreds of thousands of ticks, even with both cores busy.
    assert ticks > 50000, (elapsed, ticks)
    # One engine shared by two threads: its calls are serialized, the TOD the same.
    shared = [np.zeros(60000), np.zeros(60000)]
    threads = [threading.Thread(target=lambda k=k: engines[0].convolve(k, theta, phi, psi, out=shared[k]))
               for k in range(2)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert np.array_equal(shared[0], sequential[0]) and np.array_equal(shared[1], sequential[1])


def test_vulkan_backend_agrees_with_the_reference():
    available = {b.name: b.available for b in pisco.devices()}
    assert "cpu" in available and available["cpu"]
    if not available.get("vulkan"):
        pytest.skip("no Vulkan device: " + next(b.detail for b in pisco.devices() if b.name == "vulkan"))
    sky, beam, fp = small_setup()
    theta, phi, psi = pointing(2000)
    with pisco.Engine(sky, beam, fp, backend="cpu") as cpu, pisco.Engine(sky, beam, fp, backend="vulkan") as vk, \
            pisco.Engine(sky, beam, fp, backend="vulkan", arithmetic="float-float") as ff:
        assert "float-float" in ff.device
        for det in range(3):
            a = cpu.convolve(det, theta, phi, psi)
            for engine in (vk, ff):
                b = engine.convolve(det, theta, phi, psi)
                assert np.sqrt(np.mean((a - b) ** 2) / np.mean(a**2)) < 1e-5
    with pytest.raises(pisco.InputError, match='arithmetic: expected "auto", "float64" or "float-float", got "float128"'):
        pisco.Engine(sky, beam, fp, backend="vulkan", arithmetic="float128")


def test_engine_settings_have_the_words_of_simulation_files():
    """Engine's keywords go through the library's one table of settings (pisco::set_engine_option): its
    errors are pisco.InputError, also a ValueError, named by the keyword, in the words a simulation file's
    [engine] table and pisco-vk give for the same mistake."""
    sky = pisco.Sky(8)
    beam = pisco.Beamsor.gaussian(np.radians(8.0), np.radians(20.0))
    fp = pisco.FocalPlane()
    fp.add("d")
    assert issubclass(pisco.InputError, ValueError) and issubclass(pisco.InputError, pisco.Error)
    for kwargs, message in [
        (dict(normalization="per-sample"), 'normalization: expected "integral" or "per_sample", got "per-sample"'),
        (dict(quadrature="exact"), 'quadrature: expected "corrected" or "plain", got "exact"'),
        (dict(unseen="mask"), 'unseen: expected "error", "zero" or "flag", got "mask"'),
        (dict(backend="cpu", arithmetic="float64"), "arithmetic: the cpu backend has no arithmetic setting"),
    ]:
        with pytest.raises(pisco.InputError) as raised:
            pisco.Engine(sky, beam, fp, backend=kwargs.pop("backend", "cpu"), **kwargs)
        assert str(raised.value).startswith(message), (kwargs, str(raised.value))


def vulkan_auto_device():
    """(index, part of the name) of the device the vulkan backend's "auto" takes, from pisco.devices()."""
    info = next(b for b in pisco.devices() if b.name == "vulkan")
    if not info.available:
        pytest.skip("no Vulkan device: " + info.detail)
    # "0: llvmpipe (LLVM 15.0.6, 256 bits) [cpu, Vulkan 1.3, float64]; 1: ... (auto: llvmpipe (...) [...])"
    auto = re.search(r"\(auto: (.*)\)$", info.detail).group(1)
    index = re.search(r"(?:^|; )(\d+): " + re.escape(auto), info.detail).group(1)
    return index, auto.split()[0]


def test_vulkan_device_by_index_and_name():
    index, part = vulkan_auto_device()
    sky, beam, fp = small_setup()
    theta, phi, psi = pointing(1000)
    with pisco.Engine(sky, beam, fp, backend="vulkan") as default:
        reference = [default.convolve(det, theta, phi, psi) for det in range(3)]
        device = default.device
    assert part in device
    for request in (index, part):
        with pisco.Engine(sky, beam, fp, backend="vulkan", device=request) as engine:
            assert engine.backend == "vulkan" and engine.device == device, (request, engine.device)
            for det in range(3):
                assert np.array_equal(engine.convolve(det, theta, phi, psi), reference[det]), (request, det)
    with pytest.raises(pisco.Error, match="vulkan: no device named 'no-such-gpu'"):
        pisco.Engine(sky, beam, fp, backend="vulkan", device="no-such-gpu")
    with pytest.raises(pisco.Error, match="vulkan: device index 999 is out of range"):
        pisco.Engine(sky, beam, fp, backend="vulkan", device="999")


def test_settings_the_named_backend_lacks_are_errors():
    """device, threads, chunk_samples and arithmetic go to the backends that have them; on a named backend
    without the setting, a value other than the default is an InputError naming it."""
    sky, beam, fp = small_setup()
    with pisco.Engine(sky, beam, fp, backend="cpu", device="auto", threads=1, chunk_samples=0) as engine:
        assert engine.backend == "cpu"
    cases = [
        (dict(backend="cpu", device="0"), "device: the cpu backend has no device setting (it applies to simd, vulkan and cuda)"),
        (dict(backend="cpu", chunk_samples=10), "chunk_samples: the cpu backend has no chunk_samples setting"),
        (dict(backend="cpu", arithmetic="float64"), "arithmetic: the cpu backend has no arithmetic setting (it applies to vulkan)"),
        (dict(backend="vulkan", threads=2), "threads: the vulkan backend has no threads setting (it applies to cpu and simd)"),
    ]
    for kwargs, message in cases:
        with pytest.raises(pisco.InputError, match=re.escape(message)):
            pisco.Engine(sky, beam, fp, **kwargs)


# --- masked skies --------------------------------------------------------------------------------


def ring_pixel_centres(nside, pixels):
    """(theta, phi) of HEALPix RING pixel centres (Gorski et al. 2005, eqs. 4 to 9), in numpy."""
    p = np.asarray(pixels, dtype=np.int64)
    npix, ncap = 12 * nside * nside, 2 * nside * (nside - 1)
    z, phi = np.empty(p.size), np.empty(p.size)
    north, south = p < ncap, p >= npix - ncap
    belt = ~north & ~south
    i = np.floor((1 + np.sqrt(1 + 2 * p[north])) / 2).astype(np.int64)
    j = p[north] - 2 * i * (i - 1) + 1
    z[north], phi[north] = 1 - i**2 / (3.0 * nside**2), (j - 0.5) * np.pi / (2 * i)
    q = p[belt] - ncap
    i, j = q // (4 * nside) + nside, q % (4 * nside) + 1
    z[belt] = 4.0 / 3 - 2.0 * i / (3 * nside)
    phi[belt] = (j - np.where((i + nside) % 2 == 1, 1.0, 0.5)) * np.pi / (2 * nside)
    q = npix - p[south]
    i = np.floor((1 + np.sqrt(2 * q - 1)) / 2).astype(np.int64)
    j = 4 * i + 1 - (q - 2 * i * (i - 1))
    z[south], phi[south] = -1 + i**2 / (3.0 * nside**2), (j - 0.5) * np.pi / (2 * i)
    return np.arccos(z), phi


def unit_vectors(theta, phi):
    return np.stack([np.sin(theta) * np.cos(phi), np.sin(theta) * np.sin(phi), np.cos(theta)], axis=-1)


NSIDE_MASKED = 32
# A cluster of four pixels, two lone ones, and one UNSEEN in Q only (a mask is per pixel, any map).
MASK_I = [3000, 3001, 3128, 3129, 7000, 11900]
MASK_Q = [5000]


def masked_setup():
    """The sky of small_setup, the same sky with UNSEEN pixels, and pointing near them and elsewhere."""
    sky, beam, fp = small_setup(nside=NSIDE_MASKED, fwhm=2 * deg)
    maps = np.array([sky.I, sky.Q, sky.U])
    maps[0, MASK_I] = pisco.unseen
    maps[1, MASK_Q] = pisco.unseen
    masked = pisco.Sky.from_maps(maps, units="uK_CMB")
    rng = np.random.default_rng(12)
    centres = unit_vectors(*ring_pixel_centres(NSIDE_MASKED, MASK_I + MASK_Q))
    # Half the samples within 8 deg of a masked pixel (the disc is 5 deg), half anywhere.
    near = centres[rng.integers(0, len(centres), 1500)] + rng.normal(scale=0.07, size=(1500, 3))
    near /= np.linalg.norm(near, axis=1)[:, None]
    theta0, phi0, _ = pointing(1500, seed=13)
    theta = np.concatenate([np.arccos(np.clip(near[:, 2], -1, 1)), theta0])
    phi = np.concatenate([np.arctan2(near[:, 1], near[:, 0]) % (2 * np.pi), phi0])
    psi = rng.uniform(-np.pi, np.pi, theta.size)
    return sky, masked, beam, fp, (theta, phi, psi)


def test_ring_pixel_centres_are_healpix_pixels():
    nside = NSIDE_MASKED
    pixels = np.arange(12 * nside * nside)
    theta, phi = ring_pixel_centres(nside, pixels)
    assert all(pisco.ang2pix(nside, t, f) == p for p, t, f in zip(pixels, theta, phi))


def test_masked_sky_policies():
    sky, masked, beam, fp, (theta, phi, psi) = masked_setup()
    mask = sorted(MASK_I + MASK_Q)
    assert np.array_equal(masked.unseen_pixels(), mask) and masked.unseen_pixels().dtype == np.int64
    assert sky.unseen_pixels().size == 0
    # By default a masked sky is an error naming the map, the count and the first pixel.
    with pytest.raises(pisco.Error, match=r"sky: the Stokes I map has 6 UNSEEN pixels .* the first at pixel 3000 "):
        pisco.Engine(masked, beam, fp, backend="cpu")
    with pytest.raises(pisco.Error, match="the Stokes I map has 6 UNSEEN pixels"):
        pisco.Engine(masked, beam, fp, backend="cpu", unseen="error")
    for bad in ("mask", "", "ERROR"):
        with pytest.raises(ValueError, match=f'unseen: expected "error", "zero" or "flag", got "{bad}"'):
            pisco.Engine(masked, beam, fp, backend="cpu", unseen=bad)
    # zero: exactly the convolution of the sky with those pixels set to 0 (in every map).
    zeroed = pisco.Sky.from_maps(np.array([masked.I, masked.Q, masked.U]), units="uK_CMB")
    assert zeroed.zero_unseen() == len(mask) and zeroed.unseen_pixels().size == 0
    assert zeroed.I[3000] == 0.0 and zeroed.Q[5000] == 0.0 and zeroed.I[5000] == sky.I[5000]
    with pisco.Engine(masked, beam, fp, backend="cpu", unseen="zero", quadrature="plain") as zero, \
            pisco.Engine(zeroed, beam, fp, backend="cpu", quadrature="plain") as reference, \
            pisco.Engine(masked, beam, fp, backend="cpu", unseen="flag", quadrature="plain") as flag, \
            pisco.Engine(sky, beam, fp, backend="cpu", unseen="flag", quadrature="plain") as unmasked:
        assert (zero.unseen_pixels, flag.unseen_pixels, unmasked.unseen_pixels) == (len(mask), len(mask), 0)
        for det in range(len(fp)):
            tod = zero.convolve(det, theta, phi, psi)
            assert np.array_equal(tod, reference.convolve(det, theta, phi, psi))
            assert np.array_equal(flag.convolve(det, theta, phi, psi), tod)
            # Without UNSEEN pixels, or with another policy, nothing is flagged.
            assert not unmasked.flag_samples(det, theta, phi, psi).any()
            assert not zero.flag_samples(det, theta, phi, psi).any()
        # The sky itself is left as it was given.
        assert np.array_equal(masked.unseen_pixels(), mask)


def test_flags_are_the_discs_holding_a_masked_pixel():
    """flag_samples: exactly the samples with a masked pixel centre within rho_max of the detector's
    line of sight (HEALPix query_disc, not inclusive), by brute force; the unflagged samples are the
    unmasked sky's TOD bit for bit, the flagged ones not."""
    sky, masked, beam, fp, (theta, phi, psi) = masked_setup()
    centres = unit_vectors(*ring_pixel_centres(NSIDE_MASKED, MASK_I + MASK_Q))
    bore = np.array([pisco.quat_from_pointing(t, p, s) for t, p, s in zip(theta, phi, psi)])
    with pisco.Engine(masked, beam, fp, backend="cpu", unseen="flag", quadrature="plain") as flag, \
            pisco.Engine(sky, beam, fp, backend="cpu", quadrature="plain") as unmasked:
        for det in range(len(fp)):
            flags = flag.flag_samples(det, theta, phi, psi)
            assert flags.dtype == np.bool_ and flags.shape == theta.shape
            # The detector's line of sight: the boresight rotation, then its offset.
            q = pisco.quat_multiply(bore, fp[det].offset)
            los = unit_vectors(*np.array([pisco.quat_to_pointing(r)[:2] for r in q]).T)
            distance = np.arccos(np.clip(los @ centres.T, -1, 1)).min(axis=1)
            expected = distance <= beam.rho_max
            edge = np.abs(distance - beam.rho_max) < 1e-9  # a centre on the disc's edge may fall either way
            assert np.array_equal(flags[~edge], expected[~edge]), np.flatnonzero(flags != expected)
            assert edge.sum() <= 2
            print(f"masked sky, detector {fp.names[det]}: {flags.sum()} of {flags.size} samples flagged")
            assert 300 < flags.sum() < 1500
            # Quaternion pointing: the same flags, to a disc edge falling either way in rounding.
            assert np.sum(flag.flag_samples(fp.names[det], boresight_quats=bore) != flags) <= 2
            tod = flag.convolve(det, theta, phi, psi)
            reference = unmasked.convolve(det, theta, phi, psi)
            assert np.array_equal(tod[~flags], reference[~flags])
            assert np.all(tod[flags] != reference[flags])
        # Arguments are checked as convolve's are.
        with pytest.raises(ValueError, match=r"theta\[3\] is nan"):
            flag.flag_samples(0, np.where(np.arange(theta.size) == 3, np.nan, theta), phi, psi)
        with pytest.raises(TypeError, match="flag_samples: give either theta, phi and psi"):
            flag.flag_samples(0)
        with pytest.raises(TypeError, match=r"phi: expected float64 values, got a float32"):
            flag.flag_samples(0, theta, phi.astype(np.float32), psi)
        with pytest.raises(KeyError, match="no detector named 'x'"):
            flag.flag_samples("x", theta, phi, psi)
        assert flag.flag_samples(0, theta[:0], phi[:0], psi[:0]).shape == (0,)
    flag.close()
    with pytest.raises(ValueError, match="used after close"):
        flag.flag_samples(0, theta, phi, psi)


def test_read_fits_unseen_policies(tmp_out):
    _, masked, _, _, _ = masked_setup()
    path = tmp_out / "masked.fits"
    masked.write_fits(path)
    with pytest.raises(pisco.Error, match=r"masked.fits: column 1 \(I_STOKES\) has 6 UNSEEN pixels .* "
                                          r"the first at pixel 3000 \(RING\)"):
        pisco.Sky.read_fits(path)
    zero = pisco.Sky.read_fits(path, unseen="zero")
    assert zero.unseen_pixels().size == 0 and zero.I[7000] == 0.0 and zero.Q[5000] == 0.0
    assert zero.I[5000] == masked.I[5000]
    kept = pisco.Sky.read_fits(str(path), unseen="flag")
    assert np.array_equal(kept.unseen_pixels(), sorted(MASK_I + MASK_Q)) and kept.I[7000] == pisco.unseen
    with pytest.raises(ValueError, match='unseen: expected "error", "zero" or "flag", got "skip"'):
        pisco.Sky.read_fits(path, unseen="skip")


# --- half-wave plates ----------------------------------------------------------------------------

# The ideal plate plus leakage in all 16 entries, a 2% loss in M_II keeping it passive
# (tools/hwp_compare.py's generic plate).
GENERIC_PLATE = np.diag([1.0, 1.0, -1.0, -1.0]) + np.array([[-0.02, 0.012, -0.008, 0.005],
                                                           [0.021, -0.03, 0.017, -0.011],
                                                           [-0.015, 0.009, 0.025, 0.04],
                                                           [0.007, -0.02, 0.033, 0.02]])


def test_half_wave_plate_objects():
    ideal = pisco.HalfWavePlate()
    assert ideal.is_ideal and ideal.placement == "aperture" and ideal.gamma == 0.0
    assert np.array_equal(ideal.mueller, np.diag([1.0, 1.0, -1.0, -1.0]))
    assert np.array_equal(pisco.ideal_hwp_mueller(), ideal.mueller) and not ideal.mueller.flags.writeable
    plate = pisco.HalfWavePlate(GENERIC_PLATE, placement="detector", gamma=0.4)
    assert not plate.is_ideal and np.array_equal(plate.mueller, GENERIC_PLATE) and plate.placement == "detector"
    assert pisco.HalfWavePlate(np.diag([1, 1, -1, -1])).is_ideal  # an int array is taken too
    # M(theta) = R(-theta) M0 R(theta), theta = h - gamma.
    a = 0.9
    c, s = np.cos(2 * a), np.sin(2 * a)
    r = np.array([[1, 0, 0, 0], [0, c, s, 0], [0, -s, c, 0], [0, 0, 0, 1.0]])
    expected = r.T @ GENERIC_PLATE @ r
    assert np.allclose(pisco.rotated_mueller(GENERIC_PLATE, a), expected, rtol=0, atol=1e-15)
    assert np.allclose(plate.mueller_at(a + 0.4), expected, rtol=0, atol=1e-15)
    plate.gamma, plate.placement, plate.mueller = 0.1, "aperture", pisco.ideal_hwp_mueller()
    assert plate == pisco.HalfWavePlate(gamma=0.1) and plate != ideal
    d = pisco.Detector("d", zeta=0.2, hwp=plate)
    assert d.hwp == plate and "HalfWavePlate" in repr(d)
    d.hwp = None
    assert d.hwp is None
    fp = pisco.FocalPlane()
    fp.add("x", hwp=plate)
    fp.add(pisco.Detector("y"), hwp=pisco.HalfWavePlate(gamma=0.3))
    fp.add_pair("p", zeta=0.5, hwp=pisco.HalfWavePlate(gamma=0.5))
    fp.add_pair("q")
    assert fp["x"].hwp == plate and fp["y"].hwp.gamma == 0.3
    assert fp["pa"].hwp.gamma == 0.5 and fp["pb"].hwp.gamma == pytest.approx(0.5 - np.pi / 2)
    assert fp["qa"].hwp is None and fp["qb"].hwp is None
    # From tables: the hwp_gamma column, else the detector's polarization angle (offset gamma + zeta).
    cols = pisco.FocalPlane.from_columns({"name": ["a", "b"], "zeta": [0.1, 0.2], "xi": [0, 0], "eta": [0, 0],
                                          "gamma": [0.3, 0.0]}, hwp=pisco.HalfWavePlate(GENERIC_PLATE))
    assert cols["a"].hwp.gamma == pytest.approx(0.4) and cols["b"].hwp.gamma == pytest.approx(0.2)
    assert np.array_equal(cols["b"].hwp.mueller, GENERIC_PLATE)
    cols = pisco.FocalPlane.from_columns({"name": ["a"], "hwp_gamma": [0.7]}, hwp=pisco.HalfWavePlate())
    assert cols["a"].hwp.gamma == 0.7
    assert pisco.FocalPlane.from_columns({"name": ["a"], "hwp_gamma": [0.7]})["a"].hwp is None


def test_half_wave_plate_errors():
    cases = [
        (ValueError, r"mueller: expected a \(4, 4\) Mueller matrix .* got shape \(16,\)",
         dict(mueller=np.eye(4).ravel())),
        (ValueError, r"mueller: expected a \(4, 4\).* got shape \(3, 3\)", dict(mueller=np.eye(3))),
        (ValueError, r"mueller\[2\]\[1\] is nan", dict(mueller=np.where(np.arange(16).reshape(4, 4) == 9, np.nan,
                                                                          np.eye(4)))),
        (ValueError, r"mueller\[0\]\[0\] is inf", dict(mueller=np.diag([np.inf, 1, 1, 1]))),
        (TypeError, r"mueller: expected a \(4, 4\) Mueller matrix of numbers, got str", dict(mueller="ideal")),
        (TypeError, r"mueller: expected a real", dict(mueller=np.eye(4, dtype=complex))),
        (ValueError, r"placement: expected 'aperture' or 'detector', got 'sky'", dict(placement="sky")),
        (ValueError, r"gamma is nan", dict(gamma=np.nan)),
    ]
    for error, message, kwargs in cases:
        with pytest.raises(error, match=message):
            pisco.HalfWavePlate(**kwargs)
    plate = pisco.HalfWavePlate()
    with pytest.raises(ValueError, match=r"mueller\[3\]\[3\] is nan"):
        plate.mueller = np.diag([1, 1, 1, np.nan])
    with pytest.raises(ValueError, match="gamma is inf"):
        plate.gamma = np.inf
    with pytest.raises(ValueError, match=r"m0: expected a \(4, 4\)"):
        pisco.rotated_mueller(np.zeros(4), 0.1)
    with pytest.raises(TypeError,
                       match=r"hwp: expected a pisco.HalfWavePlate or None, got float64 array of shape \(4, 4\)"):
        pisco.Detector("d", hwp=np.eye(4))
    with pytest.raises(TypeError, match="hwp: expected a pisco.HalfWavePlate"):
        pisco.FocalPlane().add("d", hwp="ideal")
    with pytest.raises(TypeError, match="hwp: expected a pisco.HalfWavePlate"):
        pisco.FocalPlane.from_columns({"name": ["a"]}, hwp=np.eye(4))


def plate_setup(mueller=None, placement="aperture", nside=32, fwhm=2 * deg):
    """A sky, a round beam, and the same detectors with and without plates (gamma not zero): a
    detector turned about its line of sight, one off the boresight, a PSB pair."""
    rng = np.random.default_rng(4)
    sky = pisco.Sky.from_maps(rng.normal(size=(4, 12 * nside * nside)))
    beam = pisco.Beamsor.gaussian(fwhm, rho_max=2.5 * fwhm)
    with_plate, without = pisco.FocalPlane(), pisco.FocalPlane()
    for fp, plate in ((with_plate, True), (without, False)):
        def hwp(gamma):
            return pisco.HalfWavePlate(mueller, placement=placement, gamma=gamma) if plate else None

        fp.add("turned", zeta=0.3, epsilon=0.05, gain=1.2, offset=pisco.offset_quat(0.0, 0.0, 0.2), hwp=hwp(0.7))
        fp.add("off", zeta=-0.4, offset=pisco.offset_quat(1 * deg, -0.5 * deg, 0.1), hwp=hwp(-0.3))
        fp.add_pair("p", zeta=0.1, epsilon=0.02, hwp=hwp(1.1))
    return sky, beam, with_plate, without


def test_ideal_plate_identity():
    """With an ideal plate and a round beam, d(psi, h) is the plate-less d(psi + 2 (h - gamma)) for a
    detector on the boresight (float64, cpu backend)."""
    sky, beam, with_plate, without = plate_setup()
    theta, phi, psi = pointing(2000, seed=5)
    h = np.random.default_rng(6).uniform(-np.pi, 2 * np.pi, 2000)
    quats = np.array([pisco.quat_from_pointing(t, p, s) for t, p, s in zip(theta, phi, psi)])
    with pisco.Engine(sky, beam, with_plate, backend="cpu") as plated, \
            pisco.Engine(sky, beam, without, backend="cpu") as plain:
        for det in ("turned", "pa", "pb"):
            gamma = with_plate[det].hwp.gamma
            tod = plated.convolve(det, theta, phi, psi, hwp_angle=h)
            expected = plain.convolve(det, theta, phi, psi + 2 * (h - gamma))
            err = relative(tod, expected)
            print(f"ideal-plate identity, detector {det} (gamma {gamma}): {err:.1e} of the TOD's RMS")
            assert err <= 1e-12
            # Quaternions, submit/wait and accumulate give the same TOD.
            assert relative(plated.convolve(det, boresight_quats=quats, hwp_angle=h), tod) <= 1e-12
            out = np.ones(2000)
            plated.wait(plated.submit(det, theta, phi, psi, out=out, accumulate=True, hwp_angle=h))
            assert np.array_equal(out, tod + 1.0)
        # The plate does modulate: the angle's other sense gives another TOD.
        assert relative(plated.convolve("turned", theta, phi, psi, hwp_angle=-h),
                        plated.convolve("turned", theta, phi, psi, hwp_angle=h)) > 0.1


def relative(test, reference):
    return float(np.sqrt(np.mean((test - reference) ** 2) / np.mean(reference**2)))


def test_hwp_angle_errors():
    sky, beam, with_plate, without = plate_setup()
    theta, phi, psi = pointing(20)
    h = np.linspace(0, 1, 20)
    engine = pisco.Engine(sky, beam, with_plate, backend="cpu")
    cases = [
        (TypeError, r"hwp_angle: expected float64 values, got a float32", h.astype(np.float32)),
        (TypeError, r"hwp_angle: expected a numpy array of float64, got list", list(h)),
        (ValueError, r"hwp_angle: expected shape \(n,\)", h.reshape(20, 1)),
        (ValueError, r"hwp_angle: the array is not C-contiguous", np.repeat(h, 2)[::2]),
        (ValueError, r"hwp_angle: 19 samples, but the pointing has 20", h[:19]),
        (ValueError, r"hwp_angle\[4\] is nan: the plate's angles must be finite",
         np.where(np.arange(20) == 4, np.nan, h)),
        (ValueError, r"hwp_angle\[0\] is -inf", np.where(np.arange(20) == 0, -np.inf, h)),
    ]
    for error, message, angles in cases:
        with pytest.raises(error, match=message):
            engine.convolve(0, theta, phi, psi, hwp_angle=angles)
        with pytest.raises(error, match=message):
            engine.submit(0, theta, phi, psi, out=np.zeros(20), hwp_angle=angles)
    # The engine's own rules, with its message: a plate needs angles, no plate takes none.
    with pytest.raises(pisco.Error, match="detector 'turned' has a half-wave plate: expected 20 plate angles"):
        engine.convolve("turned", theta, phi, psi)
    with pytest.raises(pisco.Error, match="has a half-wave plate"):
        engine.submit("turned", theta, phi, psi, out=np.zeros(20))
    plain = pisco.Engine(sky, beam, without, backend="cpu")
    with pytest.raises(pisco.Error, match="detector 'turned' has no half-wave plate, but plate angles"):
        plain.convolve("turned", theta, phi, psi, hwp_angle=h)
    # Read-only angles are fine (they are only read), and nothing was written by the failures.
    ro = h.copy()
    ro.flags.writeable = False
    out = np.full(20, 7.0)
    with pytest.raises(pisco.Error):
        plain.convolve(0, theta, phi, psi, out=out, hwp_angle=h)
    assert np.all(out == 7.0)
    assert np.array_equal(engine.convolve(0, theta, phi, psi, hwp_angle=ro),
                          engine.convolve(0, theta, phi, psi, hwp_angle=h))


@pytest.mark.parametrize("placement", ["aperture", "detector"])
def test_vulkan_agrees_with_the_reference_through_a_generic_plate(placement):
    available = {b.name: b.available for b in pisco.devices()}
    if not available.get("vulkan"):
        pytest.skip("no Vulkan device: " + next(b.detail for b in pisco.devices() if b.name == "vulkan"))
    sky, beam, with_plate, _ = plate_setup(GENERIC_PLATE, placement)
    sky.I[:] += 2.725  # a monopole: the plate's M_QI turns it into polarization
    theta, phi, psi = pointing(3000, seed=8)
    h = np.random.default_rng(9).uniform(0, 2 * np.pi, 3000)
    with pisco.Engine(sky, beam, with_plate, backend="cpu") as cpu, \
            pisco.Engine(sky, beam, with_plate, backend="vulkan") as vk:
        worst = 0.0
        for det in range(len(with_plate)):
            a = cpu.convolve(det, theta, phi, psi, hwp_angle=h)
            b = vk.convolve(det, theta, phi, psi, hwp_angle=h)
            worst = max(worst, relative(b, a))
        print(f"generic plate at the {placement}, vulkan ({vk.device}) vs cpu: worst relative RMS {worst:.1e}")
        assert worst < 1e-5


def test_the_optics_of_one_detector():
    """The measurement equation end to end: a uniform polarized sky gives gain/2 [(1+e) I + (1-e) ...]."""
    sky = pisco.Sky(64)
    sky.I[:], sky.Q[:] = 2.0, 0.5
    beam = pisco.Beamsor.gaussian(2 * deg, rho_max=5 * deg)
    fp = pisco.FocalPlane()
    fp.add("d", zeta=0.0, epsilon=0.1, gain=2 / 1.1)
    # On the equator at psi = 0, theta' = theta^ (Q > 0 along theta^): chi = 0. (Q is uniform in the
    # local meridian frames, which turn slightly across the disc: 1e-7.)
    theta, phi, psi = np.full(1, np.pi / 2), np.zeros(1), np.zeros(1)
    tod = pisco.Engine(sky, beam, fp, backend="cpu", normalization="per_sample").convolve(0, theta, phi, psi)
    assert tod[0] == pytest.approx(2.0 + 0.9 / 1.1 * 0.5, rel=1e-7)


# --- a whole simulation --------------------------------------------------------------------------


def write_simulation(directory, output=""):
    """A small simulation file: a synthesized sky, one PSB pair, NSIDE 16 pixel centres at three angles."""
    path = directory / "sim.toml"
    path.write_text(
        "[sky]\nnside = 32\nlmax = 64\nseed = 3\n"
        "[beams.main]\ntype = \"gaussian\"\nfwhm_deg = 4.0\nrho_max_deg = 8.0\n"
        "[focal_plane]\n[[focal_plane.pairs]]\nname = \"p\"\nbeam = \"main\"\n"
        "[scan]\ntype = \"pixel_centres\"\nnside = 16\n"
        "[engine]\nbackend = \"cpu\"\n"
        f"[output]\ndir = \"{directory / 'out'}\"\nplots = false\nlmax = 32\n{output}"
    )
    return path


def test_simulation_runs_a_file_as_pisco_vk_does(tmp_path):
    """pisco.Simulation runs a simulation file through the library's pisco::Simulation: the files, the
    account and the figures of `pisco-vk run`, and the same maps and spectra, byte for byte."""
    path = write_simulation(tmp_path)
    sim = pisco.Simulation.from_file(path, output_dir=tmp_path / "lib")
    assert sim.source == str(path)
    assert sim.output_dir == str(tmp_path / "lib")
    assert sim.detectors == ["pa", "pb"]
    assert "pisco.Simulation(" in repr(sim)
    result = sim.run()
    n = 12 * 16 * 16 * 3
    assert result["samples"] == 2 * n
    assert result["samples_per_detector"] == n
    assert result["detectors"] == 2
    assert result["backend"] == "cpu"
    assert result["solved_pixels"] == 12 * 16 * 16
    assert result["nothing_solved"] is None
    assert result["mean_disc_pixels"] > 0 and result["convolution_seconds"] > 0 and result["seconds"] > 0
    names = ["tod.h5", "maps.fits", "hits.fits", "spectra.txt", "input_spectra.txt"]
    assert result["files"] == [str(tmp_path / "lib" / f) for f in names]
    assert result["tod"] == str(tmp_path / "lib" / "tod.h5")
    assert result["log"][0].startswith("sky: NSIDE 32, synthesized from ")
    assert "scan: pixel_centres, 2 detectors x 9216 samples" in result["log"]
    assert "maps: NSIDE 16, 3072 of 3072 pixels solved (rcond >= 0.001)" in result["log"]
    assert sorted(os.listdir(tmp_path / "lib")) == sorted(names)

    # Against the command line of the same build, where there is one.
    build = os.environ.get("PISCO_TEST_BUILD")
    exe = os.path.join(build, "tools", "pisco-vk") if build else ""
    if exe and os.path.isfile(exe) and os.access(exe, os.X_OK):
        subprocess.run([exe, "run", str(path), "-q", "--no-plots", "-o", str(tmp_path / "cli")], check=True)
        for f in names[1:]:
            assert (tmp_path / "cli" / f).read_bytes() == (tmp_path / "lib" / f).read_bytes(), f

    # The constructor is from_file; the backend and output directory may be changed before a run.
    again = pisco.Simulation(path, backend="cpu")
    again.output_dir = tmp_path / "again"
    again.backend = "cpu"
    assert again.run()["samples"] == 2 * n


def test_simulation_errors(tmp_path):
    """The library's errors as pisco.Error with pisco-vk's messages; bad arguments as ValueError."""
    bad = tmp_path / "bad.toml"
    bad.write_text("[sky]\nnside = 32\nseeed = 3\n")
    with pytest.raises(pisco.Error, match=re.escape(f"{bad}: [sky] unknown key 'seeed' (did you mean 'seed'?)")):
        pisco.Simulation.from_file(bad)
    with pytest.raises(pisco.Error, match="no such file"):
        pisco.Simulation(tmp_path / "missing.toml")
    with pytest.raises(ValueError, match="output_dir: expected a directory name"):
        pisco.Simulation(write_simulation(tmp_path), output_dir="")
    sim = pisco.Simulation(write_simulation(tmp_path, "maps_nside = 4\n"))
    with pytest.raises(pisco.Error, match=r"\[output\] lmax: expected a multipole up to 4 maps_nside = 16, got 32"):
        sim.run()
    assert os.listdir(tmp_path / "out") == []  # nothing written


def test_simulation_deconvolves_the_beams(tmp_path):
    """[mapmaker] type = "deconvolve" through pisco.Simulation: the iterations in the dict and the log,
    the deconvolved, reconvolved and binned maps written at the sky's NSIDE."""
    path = write_simulation(tmp_path, "tod = false\n[mapmaker]\ntype = \"deconvolve\"\niterations = 5\n"
                                      "target_fwhm_deg = 5.0\n")
    with pytest.warns(RuntimeWarning, match="the deconvolving map-maker did not converge: residual "):
        result = pisco.Simulation(path, backend="simd").run()
    assert result["deconvolution_iterations"] == 5
    assert result["deconvolution_converged"] is False
    assert result["warnings"][0].startswith("the deconvolving map-maker did not converge")
    assert 0 < result["deconvolution_residual"] < 1
    assert sum(line.startswith("mapmaker: iteration ") for line in result["log"]) == 5
    names = {"maps.fits", "deconvolved.fits", "binned_maps.fits", "hits.fits", "spectra.txt", "input_spectra.txt"}
    assert set(os.listdir(tmp_path / "out")) == names
    assert any(line.startswith("maps: NSIDE 32, 12288 of 12288 pixels reached") for line in result["log"])
    binned = tmp_path / "binned"
    binned.mkdir()
    assert "deconvolution_iterations" not in pisco.Simulation(write_simulation(binned)).run()


def test_simulation_releases_the_gil(tmp_path):
    """Other Python threads run while a simulation runs."""
    sim = pisco.Simulation(write_simulation(tmp_path, "tod = false\nspectra = false\n"))
    thread = threading.Thread(target=sim.run)
    ticks = 0
    thread.start()
    while thread.is_alive():
        ticks += 1
        time.sleep(0.001)
    thread.join()
    assert ticks > 5
    assert os.path.exists(tmp_path / "out" / "maps.fits")


def test_simulation_locks_its_output_directory(tmp_path):
    """pisco.Simulation takes the lock pisco-vk run takes: a second run into a directory another process
    is writing is refused, naming that process; once that process is killed, the next run removes the
    temporaries it left, and only those; a lock file that links to a user's file is refused and the file
    kept."""
    slow = tmp_path / "slow.toml"
    slow.write_text(write_simulation(tmp_path).read_text().replace("nside = 16\n", "nside = 128\n")
                    .replace("nside = 32\n", "nside = 64\n"))
    out = tmp_path / "out"
    out.mkdir()
    (out / "notes.tmp-20261127").write_text("a user's notes")
    child = subprocess.Popen([sys.executable, "-c", f"import pisco; pisco.Simulation({str(slow)!r}).run()"])
    try:
        deadline = time.monotonic() + 120
        while not any(".tmp-pisco-" in f for f in os.listdir(out)):
            assert child.poll() is None, "the first run ended before it wrote"
            assert time.monotonic() < deadline
            time.sleep(0.01)
        with pytest.raises(pisco.Error, match=re.escape(f"{out}: another pisco-vk run (process {child.pid})")):
            pisco.Simulation(write_simulation(tmp_path)).run()
    finally:
        child.kill()
        child.wait()
    left = [f for f in os.listdir(out) if ".tmp-pisco-" in f]
    assert left, "the killed run left no temporary file"
    result = pisco.Simulation(write_simulation(tmp_path)).run()
    assert any(f"a temporary file left by process {child.pid}, which has ended" in line for line in result["log"])
    assert not any(".tmp-pisco-" in f for f in os.listdir(out))
    assert (out / "notes.tmp-20261127").read_text() == "a user's notes"
    assert not (out / ".pisco-vk.lock").exists()

    victim = tmp_path / "thesis.tex"
    victim.write_text("Chapter 1\n")
    os.symlink(victim, out / ".pisco-vk.lock")
    with pytest.raises(pisco.Error, match="is a symbolic link, not a lock file of pisco-vk"):
        pisco.Simulation(write_simulation(tmp_path)).run()
    assert victim.read_text() == "Chapter 1\n"


def test_default_hwp_gamma():
    """The plate's gamma where a table gives none: the offset's gamma plus zeta, as pisco-vk takes it."""
    d = pisco.Detector("d", zeta=0.3, offset=pisco.offset_quat(1 * deg, 2 * deg, 0.2))
    assert pisco.default_hwp_gamma(d) == pytest.approx(0.5, abs=1e-12)
    fp = pisco.FocalPlane.from_columns({"name": ["a"], "zeta": [0.3], "xi": [0.0], "gamma": [0.2]},
                                       hwp=pisco.HalfWavePlate(pisco.ideal_hwp_mueller()))
    assert fp[0].hwp.gamma == pisco.default_hwp_gamma(fp[0])


# --- the package itself --------------------------------------------------------------------------


def test_stubs_cover_the_module():
    """python/pisco/_pisco.pyi declares every public name of the compiled module, and no other."""
    stub = os.path.join(os.path.dirname(pisco.__file__), "_pisco.pyi")
    tree = ast.parse(open(stub).read())
    declared = set()
    for node in tree.body:
        if isinstance(node, (ast.ClassDef, ast.FunctionDef)):
            declared.add(node.name)
        elif isinstance(node, ast.AnnAssign):
            declared.add(node.target.id)
    declared.discard("Float64Array")
    public = {n for n in dir(pisco._pisco) if not n.startswith("_")} | {"__version__"}
    assert declared == public
    for cls in ("Sky", "Beamsor", "Detector", "FocalPlane", "Engine", "HalfWavePlate", "Simulation"):
        node = next(n for n in tree.body if isinstance(n, ast.ClassDef) and n.name == cls)
        members = {n.name for n in node.body if isinstance(n, ast.FunctionDef)}
        members |= {n.target.id for n in node.body if isinstance(n, ast.AnnAssign)}
        actual = {n for n in dir(getattr(pisco, cls)) if not n.startswith("_")}
        assert actual <= members, f"{cls}: not in the stub: {actual - members}"


def test_docstrings_and_version():
    assert pisco.__version__.count(".") == 2
    for obj in (pisco.Sky, pisco.Beamsor.gaussian, pisco.Engine, pisco.Engine.convolve, pisco.FocalPlane.from_toast,
                pisco.devices, pisco.HalfWavePlate, pisco.HalfWavePlate.mueller_at, pisco.rotated_mueller,
                pisco.ideal_hwp_mueller, pisco.Sky.read_fits, pisco.Sky.unseen_pixels, pisco.Engine.flag_samples):
        assert obj.__doc__ and len(obj.__doc__) > 20
    assert issubclass(pisco.Error, RuntimeError)


# --- nothing silent: the library's checks, as Python sees them ----------------------------------


def test_focal_plane_is_checked_as_the_command_line_checks_it():
    """One library check of the focal plane (pisco::check_focal_plane), made by every engine: the same
    errors as pisco-vk's, naming the detector."""
    sky, beam, _ = small_setup(nside=8, fwhm=8 * deg)

    def engine_error(fp):
        with pytest.raises(pisco.Error) as info:
            pisco.Engine(sky, beam, fp, backend="cpu")
        return str(info.value)

    fp = pisco.FocalPlane()
    for name in ("a", "b", "a"):
        fp.add(name)
    assert engine_error(fp) == "focal plane: detectors 0 and 2 are both named 'a' (expected unique detector names)"
    fp = pisco.FocalPlane()
    fp.add("")
    assert engine_error(fp) == "focal plane: detector 0 has an empty name (expected unique names)"
    for gain, text in ((0.0, "0"), (-1.0, "-1"), (np.nan, "nan"), (np.inf, "inf")):
        fp = pisco.FocalPlane()
        fp.add("g", gain=gain)
        assert engine_error(fp) == f"detector 'g': gain = {text} (its responsivity) must be positive and finite"
    fp = pisco.FocalPlane()
    fp.add("e", epsilon=-0.1)
    assert engine_error(fp) == "detector 'e': epsilon = -0.1 (cross-polar leakage) is outside [0, 1]"


def test_offsets_are_unit_quaternions():
    """Offsets further than pisco.unit_quat_tolerance from unit norm are refused (ValueError naming the
    argument and the norm), never normalized; within it the rounding is normalized away."""
    assert pisco.unit_quat_tolerance == 1e-6
    with pytest.raises(ValueError, match=r"^offset: the quaternion \(0, 0, 0, 2\) has norm 2 \(expected a unit "
                                         r"quaternion x, y, z, w, to within 1e-06\)$"):
        pisco.Detector("d", offset=[0, 0, 0, 2])
    with pytest.raises(ValueError, match=r"^offset: .* has norm 1.0000100000000001 \(expected"):
        pisco.FocalPlane().add("d", offset=[0, 0, 0, 1 + 1e-5])
    d = pisco.Detector("d")
    with pytest.raises(ValueError, match=r"^offset: the quaternion \(0.5, 0, 0, 0.5\) has norm 0.70710678118654757 \(expected"):
        d.offset = [0.5, 0, 0, 0.5]
    assert np.array_equal(d.offset, [0, 0, 0, 1])  # unchanged
    d.offset = [0, 0, 0, 1 + 1e-9]
    assert d.offset[3] == 1.0
    with pytest.raises(ValueError, match=r"^q: the quaternion .* has norm 3"):
        pisco.quat_to_pointing([0, 0, 0, 3])
    # A table's quaternions: named by row and detector.
    with pytest.raises(ValueError, match=r"^columns: 'quat' row 1 \(detector b\): offset: the quaternion .* has norm 1.1"):
        pisco.FocalPlane.from_columns({"name": ["a", "b"], "quat": [[0, 0, 0, 1], [0, 0, 0, 1.1]]})


def test_unsigned_arguments_refuse_negative_values_by_name():
    sky, beam, fp = small_setup(nside=8, fwhm=8 * deg)
    engine = pisco.Engine(sky, beam, fp, backend="cpu")
    d = pisco.Detector("d")

    def set_beam():
        d.beam = -1

    calls = {
        "threads": lambda: pisco.Engine(sky, beam, fp, backend="cpu", threads=-1),
        "chunk_samples": lambda: pisco.Engine(sky, beam, fp, backend="cpu", chunk_samples=-5),
        "beam": lambda: pisco.Detector("d", beam=-1),
        "beam_b": lambda: pisco.FocalPlane().add_pair("p", beam_b=-2),
        "ticket": lambda: engine.wait(-3),
    }
    for name, call in calls.items():
        with pytest.raises(ValueError, match=rf"^{name} = -\d is negative; expected a non-negative integer$"):
            call()
    for call in (set_beam, lambda: pisco.FocalPlane().add("d", beam=-1),
                 lambda: pisco.FocalPlane.read_toast("no-such-file.h5", beam=-1),
                 lambda: pisco.read_toast_focal_plane("no-such-file.h5", beam=-1)):
        with pytest.raises(ValueError, match=r"^beam = -1 is negative"):
            call()
    assert d.beam == 0
    with pytest.raises(ValueError, match=r"^threads = 4294967296 is beyond 4294967295$"):
        pisco.Engine(sky, beam, fp, backend="cpu", threads=2**32)


def test_plate_and_beam_mueller_bounds():
    """A plate's M0 is a passive element's (docs/physics.md, "Physical bounds on Mueller matrices"), a
    beam's constant matrix a Mueller matrix up to scale: ValueError naming `mueller` and the bound."""
    assert pisco.mueller_tolerance == 0.01
    ideal = np.diag([1.0, 1.0, -1.0, -1.0])
    cases = [
        (np.diag([-1.0, 1, -1, -1]), r"^mueller: M00 = -1 \(T to T\) is not positive"),
        (ideal + np.pad([[0, 1e200]], ((0, 3), (0, 2))),
         r"^mueller: transmits up to 1e\+200 times the light \(M00 \+ \|\(M01, M02, M03\)\| = 1e\+200\), at most 1.01 "
         r"for a passive element$"),
        (np.diag([1.0, 0.5, -0.5, -0.5]) + np.pad([[0.0], [0.8], [0.8]], ((0, 1), (0, 3))),
         r"^mueller: polarizes unpolarized light to a degree of 1.13137 \(\|\(M10, M20, M30\)\| / M00\), at most 1.01"),
        (np.diag([1.0, 1.0, -1.5, -1.0]), r"^mueller: \|M22\| = 1.5 exceeds \(1 \+ 0.01\) M00 = 1.01"),
    ]
    for m, message in cases:
        with pytest.raises(ValueError, match=message):
            pisco.HalfWavePlate(m)
    plate = pisco.HalfWavePlate()
    with pytest.raises(ValueError, match=r"^mueller: transmits up to 1.05 times"):
        plate.mueller = np.diag([1.05, 1, -1, -1])
    assert plate.is_ideal  # the refused assignment changed nothing
    plate.mueller = GENERIC_PLATE  # a plate a little off its design, with a 2% loss
    # A beam's constant matrix: M00 > 0, no entry above it; any overall scale.
    leaky = np.eye(4)
    leaky[1, 0] = 2.0
    with pytest.raises(ValueError, match=r"^mueller: the constant Mueller matrix: \|M10\| = 2 exceeds \(1 \+ 0.01\) M00 = 1.01"):
        pisco.Beamsor.gaussian(1 * deg, mueller=leaky)
    with pytest.raises(ValueError, match=r"^mueller: the constant Mueller matrix: M00 = 0 \(T to T\) is not positive"):
        pisco.Beamsor.gaussian(1 * deg, mueller=np.diag([0.0, 1, 1, 1]))
    pisco.Beamsor.gaussian(1 * deg, mueller=1e6 * np.eye(4))

    # A field's values: finite (ValueError naming the call), no entry above the peak B_TT (pisco.Error
    # naming the beam, the entry and the node).
    def field(bad):
        def f(rho, sigma):
            m = np.exp(-rho**2 / (2 * (1 * deg) ** 2)) * np.eye(4)
            m[1, 2] = bad if rho > 1 * deg else 0.0
            return m
        return f

    with pytest.raises(ValueError, match=r"^field\([^)]*\): Mueller entry \[1\]\[2\] is nan \(expected 16 finite"):
        pisco.Beamsor.from_field(field(np.nan), 3 * deg, 0.2 * deg, "leaky")
    with pytest.raises(pisco.Error, match=r"^beam 'leaky': B_UQ \(row 1, column 2\) = 2 at node \(\d+, \d+\) \(rho = "
                                          r".*exceeds the beam's peak B_TT = 1 by more than 1%"):
        pisco.Beamsor.from_field(field(2.0), 3 * deg, 0.2 * deg, "leaky")


def test_non_finite_tod_names_the_detector_and_the_sample():
    """A sky of 1e308 is finite; through a detector of gain 100 the TOD overflows float64: pisco.Error
    naming the detector, the sample and the value, from convolve() and from wait() alike."""
    nside = 8
    sky = pisco.Sky.from_maps(np.full((1, 12 * nside * nside), 1e308))
    beam = pisco.Beamsor.gaussian(10 * deg, rho_max=20 * deg)
    fp = pisco.FocalPlane()
    fp.add("cold")
    fp.add("hot", gain=100.0)
    n = 4
    theta, phi, psi = np.full(n, np.pi / 2), np.linspace(0, 1, n), np.zeros(n)
    with pisco.Engine(sky, beam, fp, backend="cpu", quadrature="plain") as engine:
        with pytest.raises(pisco.Error, match=r"^convolving detector 'hot': sample 0 of the TOD is inf: the convolution "
                                              r"overflowed float64; .* too large for float64"):
            engine.convolve("hot", theta, phi, psi)
        cold, hot = np.zeros(n), np.zeros(n)
        engine.submit("cold", theta, phi, psi, out=cold)
        engine.submit("hot", theta, phi, psi, out=hot)
        with pytest.raises(pisco.Error, match=r"^convolving detector 'hot': sample 0"):
            engine.wait()
        engine.wait()  # nothing left half done
        assert np.all(np.isfinite(cold)) and np.all(cold > 4e307)


def run_limited(code):
    """Runs `code` in a Python whose address space is limited to 1 GiB more than it holds after
    importing pisco (what it allocates beyond that fails at once, untouched); returns its output."""
    prelude = textwrap.dedent("""
        import resource
        import numpy as np
        import pisco
        def vm_size():
            for line in open("/proc/self/status"):
                if line.startswith("VmSize:"):
                    return int(line.split()[1]) * 1024
        def limit(extra):
            resource.setrlimit(resource.RLIMIT_AS, (vm_size() + extra, resource.RLIM_INFINITY))
    """)
    done = subprocess.run([sys.executable, "-c", prelude + textwrap.dedent(code)], capture_output=True, text=True,
                          env=os.environ, timeout=300)
    assert done.returncode == 0, done.stderr
    return done.stdout.strip()


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="reads /proc/self/status")
@pytest.mark.skipif("libasan" in os.environ.get("LD_PRELOAD", ""),
                    reason="under AddressSanitizer (scripts/run-sanitizers.sh) an address-space limit fails the "
                           "sanitizer's own allocator, which aborts, before the library can see a lack of memory")
def test_memory_errors_say_what_was_too_large():
    """std::bad_alloc from the library becomes a MemoryError saying what was too large, never a crash."""
    out = run_limited("""
        limit(1 << 30)
        try:
            pisco.Sky(8192)
        except MemoryError as e:
            print(e)
    """)
    assert out == "pisco.Sky(nside=8192): 2.58e+10 bytes of maps could not be allocated"
    out = run_limited("""
        sky = pisco.Sky(256)
        beam = pisco.Beamsor.gaussian(1 * pisco.deg)
        fp = pisco.FocalPlane()
        fp.add("d")
        limit(20 << 20)
        try:
            pisco.Engine(sky, beam, fp, backend="cpu", threads=1)
        except MemoryError as e:
            print(e)
    """)
    assert out.startswith("pisco.Engine: memory ran out while setting up for a sky of NSIDE 256 (786432 pixels; "
                          "the engine keeps copies of its I, Q, U, V maps, 2.52e+07 bytes each)"), out
