"""pisco.litebird.add_convolved_sky_to_observations against litebird_sim's own 4 pi convolution (ducc0)
on the same observation, band-limited sky and Gaussian beams, without and with a half-wave plate
(litebird_sim's MuellerConvolver), and the shape of its arguments."""

import logging

import healpy as hp
import numpy as np
import pytest

import litebird_sim as lbs
import pisco
import pisco.litebird
from conftest import assert_everywhere, offset_elliptical_blm, relative_rms, smooth_sky_alm
from mueller_reference import GENERIC, IDEAL  # the ideal plate, and one with leakage in all 16 entries

FWHM_ARCMIN = 60.0
POL_ANGLES_DEG = (0.0, 90.0, 22.5)
HWP_SPEED = 2 * np.pi * 46 / 60  # LiteBIRD's LFT plate, 46 rpm, in rad/s


def observation(tmp_path, ellipticity=1.0, dtype=np.float64, seconds=600.0, hwp=None, mueller_hwp=None, psi_deg=30.0,
                start_time=0.0):
    """A litebird_sim observation of three detectors at POL_ANGLES_DEG; `ellipticity` and `psi_deg` (the
    beams' major axes) for all, or one each."""
    ellipticity = np.broadcast_to(ellipticity, len(POL_ANGLES_DEG))
    psi_deg = np.broadcast_to(psi_deg, len(POL_ANGLES_DEG))
    sim = lbs.Simulation(start_time=start_time, duration_s=seconds, random_seed=1, base_path=str(tmp_path / "lbs"),
                         imo=lbs.Imo(flatfile_location=lbs.PTEP_IMO_LOCATION))
    sim.set_scanning_strategy(lbs.SpinningScanningStrategy(spin_sun_angle_rad=np.radians(45),
                                                           precession_rate_hz=1 / 600, spin_rate_hz=1 / 60),
                              delta_time_s=1.0)
    sim.set_instrument(lbs.InstrumentInfo(name="instrument", spin_boresight_angle_rad=np.radians(50)))
    if hwp is not None:
        sim.set_hwp(hwp)
    detectors = []
    for k, angle in enumerate(POL_ANGLES_DEG):
        # Detectors off the boresight, each turned differently in the focal plane.
        quat = lbs.RotQuaternion(quats=np.array(pisco.offset_quat(np.radians(1.0 * k), np.radians(0.5),
                                                                  np.radians(10.0 * k))))
        detectors.append(lbs.DetectorInfo(name=f"det{k}", channel="ch", sampling_rate_hz=10.0,
                                          fwhm_arcmin=FWHM_ARCMIN, pol_angle_rad=np.radians(angle), quat=quat,
                                          ellipticity=float(ellipticity[k]), psi_rad=np.radians(psi_deg[k]),
                                          mueller_hwp=mueller_hwp))
    tods = [lbs.TodDescription(name=name, units=lbs.Units.K_CMB, dtype=dtype, description=name)
            for name in ("tod", "pisco", "tod2", "pisco2")]
    (obs,) = sim.create_observations(detectors=detectors, tods=tods)
    sim.prepare_pointings()
    return obs


def compare(tmp_path, nside, ellipticity, hwp=None, mueller_hwp=None, coordinates=None):
    """The sky in galactic coordinates (the default), or in `coordinates`: in ecliptic ones the scan passes
    within 2.9 deg of both HEALPix poles."""
    coordinates = coordinates or lbs.CoordinateSystem.Galactic
    lmax = 2 * nside
    mmax = 2 if ellipticity == 1.0 else 24
    obs = observation(tmp_path, ellipticity, hwp=hwp, mueller_hwp=mueller_hwp)
    alm = smooth_sky_alm(lmax, seed=5, smoothing_fwhm=np.radians(0.5))
    sky_alm = lbs.SphericalHarmonics(values=alm, lmax=lmax, coordinates=coordinates)
    blms = lbs.generate_gauss_beam_alms(obs, lmax=lmax, mmax=mmax)
    params = lbs.BeamConvolutionParameters(lmax=lmax, mmax=mmax, single_precision=False, epsilon=1e-8)
    lbs.add_convolved_sky_to_observations(obs, sky_alm, blms, convolution_params=params, nthreads=2)
    sky = lbs.HealpixMap(values=hp.alm2map(alm, nside, lmax=lmax, pol=True), nside=nside, coordinates=coordinates)
    pisco.litebird.add_convolved_sky_to_observations(obs, sky, component="pisco", backend="cpu")
    return obs


def test_round_beams_match_litebird_sim(tmp_path):
    """Across both poles (docs/validation.md, L): the sky in ecliptic coordinates, which the scan's
    boresight passes within 2.9 deg of at both poles."""
    obs = compare(tmp_path, nside=256, ellipticity=1.0, coordinates=lbs.CoordinateSystem.Ecliptic)
    rms = relative_rms(obs.pisco, obs.tod)
    per_detector = [relative_rms(obs.pisco[i], obs.tod[i]) for i in range(len(POL_ANGLES_DEG))]
    pointings, _ = obs.get_pointings("all")
    theta = np.array([p[:, 0] for p in pointings])
    near = np.minimum(theta, np.pi - theta) < np.radians(10)
    print(f"pisco.litebird vs litebird_sim 4 pi convolution: {obs.tod.shape[0]} detectors x {obs.tod.shape[1]} "
          f"samples, sky NSIDE 256 (lmax 512), FWHM 1 deg, polarization angles {POL_ANGLES_DEG} deg: relative RMS "
          f"{rms:.2e} (per detector {', '.join(f'{r:.2e}' for r in per_detector)}); {near.sum()} samples within 10 "
          f"deg of the poles (closest {np.degrees(np.minimum(theta, np.pi - theta).min()):.1f} deg): "
          f"{relative_rms(obs.pisco[near], obs.tod[near]):.2e} there")
    assert near.sum() > 300
    assert rms <= 5e-5 and max(per_detector) <= 1e-4


def test_elliptical_beams_match_litebird_sim(tmp_path):
    obs = compare(tmp_path, nside=128, ellipticity=1.5)
    rms = relative_rms(obs.pisco, obs.tod)
    print(f"elliptical beams (ellipticity 1.5, major axis at 30 deg), sky NSIDE 128: relative RMS {rms:.2e}")
    # The axis turned the other way gives 7e-2: the orientation convention is litebird_sim's.
    assert rms <= 2e-3


def away_from_poles(obs, degrees=10.0):
    """(detectors, samples) True where the detector's line of sight (galactic, as the sky) lies more than
    `degrees` from the poles."""
    from litebird_sim.coordinates import rotate_coordinates_e2g

    pointings, _ = obs.get_pointings("all")
    theta = np.array([rotate_coordinates_e2g(p)[:, 0] for p in pointings])
    return np.abs(np.cos(theta)) < np.cos(np.radians(degrees))


def convolve_beam_alms(obs, nside, lmax, lmax_beam, mmax, grid_step=np.radians(FWHM_ARCMIN / 60.0) / 40):
    """test_beam_alms_match_litebird_sim's beams (litebird_sim's elliptical b_lm for det0 and det1, one
    0.3 deg off its axis with cross-polar leakage for det2) and sky (smooth, to lmax, NSIDE nside) through
    litebird_sim's add_convolved_sky_to_observations into obs.tod and pisco.litebird's into obs.pisco,
    with the observation's plate if it has one (tools/litebird_mueller/repro_litebird.py too). Returns
    the sky's a_lm and the beams."""
    alm = smooth_sky_alm(lmax, seed=5, smoothing_fwhm=np.radians(0.5))
    sky_alm = lbs.SphericalHarmonics(values=alm, lmax=lmax, coordinates=lbs.CoordinateSystem.Galactic)
    sky = lbs.HealpixMap(values=hp.alm2map(alm, nside, lmax=lmax, pol=True), nside=nside,
                         coordinates=lbs.CoordinateSystem.Galactic)
    params = lbs.BeamConvolutionParameters(lmax=lmax, mmax=mmax, single_precision=False, epsilon=1e-8)
    blms = lbs.generate_gauss_beam_alms(obs, lmax=lmax_beam, mmax=mmax)
    blms["det2"] = lbs.SphericalHarmonics(values=offset_elliptical_blm(
        lmax_beam, mmax, np.radians(FWHM_ARCMIN / 60.0), 1.5, np.radians(25.0), psi_pol=0.0, cross_polar_leakage=0.02,
        offset=np.radians(0.3), offset_angle=np.radians(40.0)), lmax=lmax_beam, mmax=mmax)
    lbs.add_convolved_sky_to_observations(obs, sky_alm, blms, convolution_params=params, nthreads=2)
    # Sampled at FWHM / 40 unless grid_step says otherwise, out to 3 deg (5 sigma of the major axis
    # beyond the offset).
    pisco.litebird.add_convolved_sky_to_observations(obs, sky, blms, component="pisco", backend="cpu",
                                                     convolution_params=params, beam_alms_rho_max=np.radians(3.0),
                                                     beam_alms_grid_step=grid_step)
    return alm, blms


def test_beam_alms_match_litebird_sim(tmp_path):
    """litebird_sim's own beams, as its add_convolved_sky_to_observations takes them, through it and
    through pisco.litebird, as a dict by detector name: generate_gauss_beam_alms's for det0 and det1
    (elliptical, each with its ellipticity, major axis and polarization angle; mmax 12), and for det2
    (pol_angle_rad 22.5 deg) an elliptical beam with cross-polar leakage polarized along its frame's x
    axis, its centre 0.3 deg off the axis so that odd m hold coefficients too."""
    nside, lmax = 256, 512
    lmax_beam, mmax = 768, 12
    obs = observation(tmp_path, ellipticity=(1.5, 1.3, 1.6), psi_deg=(30.0, -20.0, 75.0))
    convolve_beam_alms(obs, nside, lmax, lmax_beam, mmax)
    away = away_from_poles(obs)
    rms = relative_rms(obs.pisco, obs.tod)
    per_detector = [relative_rms(obs.pisco[i], obs.tod[i]) for i in range(len(POL_ANGLES_DEG))]
    print(f"pisco.litebird vs litebird_sim with its beam_alms (lmax {lmax_beam}, mmax {mmax}; det2 0.3 deg off axis): "
          f"{obs.tod.shape[0]} detectors x {obs.tod.shape[1]} samples, sky NSIDE {nside} (lmax {lmax}): relative RMS "
          f"{rms:.2e} (per detector {', '.join(f'{r:.2e}' for r in per_detector)}); {np.count_nonzero(~away)} samples "
          f"within 10 deg of the poles")
    assert_everywhere(obs.pisco, obs.tod, away, 3e-4)


def test_beam_alms_arguments(tmp_path):
    """The b_lm stored in the observation (beams None, as litebird_sim falls back to them), mmax cut by
    convolution_params, the gain 2 Omega~ at epsilon 0, and what is refused."""
    obs = observation(tmp_path, ellipticity=1.4, seconds=20.0)
    sky = pisco.Sky.from_maps(hp.alm2map(smooth_sky_alm(128, seed=2, smoothing_fwhm=np.radians(2.0)), 64,
                                         lmax=128, pol=True))
    galactic = lbs.CoordinateSystem.Galactic
    blms = lbs.generate_gauss_beam_alms(obs, lmax=256, mmax=6, store_in_observation=True)
    small = dict(component="pisco", backend="cpu", coordinates=galactic, beam_alms_rho_max=np.radians(3.0))
    pisco.litebird.add_convolved_sky_to_observations(obs, sky, blms, **small)
    given = obs.pisco.copy()
    obs.pisco[:] = 0
    pisco.litebird.add_convolved_sky_to_observations(obs, sky, **small)
    assert np.array_equal(obs.pisco, given)
    # Each detector: from_blm(b_lm exp(i m pol_angle_rad), angle=pol_angle_rad), epsilon 0, gain 2 Omega~.
    m = np.concatenate([np.full(256 - k + 1, k) for k in range(7)])
    pointings, _ = obs.get_pointings("all")
    from litebird_sim.coordinates import rotate_coordinates_e2g

    for k, name in enumerate(obs.name):
        zeta = float(obs.pol_angle_rad[k])
        beam = pisco.Beamsor.from_blm(blms[name].values * np.exp(1j * m * zeta), rho_max=np.radians(3.0), angle=zeta,
                                      lmax=256, mmax=6)
        fp = pisco.FocalPlane()
        fp.add(name, zeta=zeta, gain=2 * beam.omega_tilde)
        p = rotate_coordinates_e2g(pointings[k])
        with pisco.Engine(sky, beam, fp, backend="cpu") as engine:
            tod = engine.convolve(0, *(np.ascontiguousarray(p[:, c]) for c in range(3)))
        assert np.array_equal(tod, given[k])
    # convolution_params cuts m as litebird_sim does.
    params = lbs.BeamConvolutionParameters(lmax=128, mmax=2)
    obs.pisco[:] = 0
    pisco.litebird.add_convolved_sky_to_observations(obs, sky, blms, convolution_params=params, **small)
    cut = obs.pisco.copy()
    assert relative_rms(cut, given) > 1e-6
    obs.pisco[:] = 0
    two = {n: lbs.SphericalHarmonics(values=b.resize_alm(256, 2).values, lmax=256, mmax=2) for n, b in blms.items()}
    pisco.litebird.add_convolved_sky_to_observations(obs, sky, two, **small)
    assert np.array_equal(obs.pisco, cut)
    # One SphericalHarmonics for all detectors, or a dict by channel: the same. The detectors'
    # pol_angle_rad does not turn it (litebird_sim's b_lm hold the polarization): their TOD differ by
    # their offsets only.
    one = blms["det1"]
    obs.pisco[:] = 0
    pisco.litebird.add_convolved_sky_to_observations(obs, sky, one, **small)
    single = obs.pisco.copy()
    obs.pisco[:] = 0
    pisco.litebird.add_convolved_sky_to_observations(obs, sky, {"ch": one}, **small)
    assert np.array_equal(obs.pisco, single)
    # det0 (pol_angle_rad 0) seen by a detector at det1's angle with the beam turned for it: the same TOD
    # (to the beams' sampling: each is synthesized on its own grid).
    zeta1 = float(obs.pol_angle_rad[1])
    assert zeta1 != 0.0
    beam = pisco.Beamsor.from_blm(one.values * np.exp(1j * m * zeta1), rho_max=np.radians(3.0), angle=zeta1, lmax=256,
                                  mmax=6)
    fp = pisco.FocalPlane()
    fp.add("at_zeta1", zeta=zeta1, gain=2 * beam.omega_tilde)
    p = rotate_coordinates_e2g(pointings[0])
    with pisco.Engine(sky, beam, fp, backend="cpu") as engine:
        assert relative_rms(engine.convolve(0, *(np.ascontiguousarray(p[:, c]) for c in range(3))), single[0]) < 1e-6
    with pytest.raises(ValueError, match="keys do not match"):
        pisco.litebird.add_convolved_sky_to_observations(obs, sky, {"other": blms["det0"]}, **small)
    bad = lbs.SphericalHarmonics(values=np.full((3, blms["det0"].values.shape[1]), np.nan, complex), lmax=256, mmax=6)
    with pytest.raises(ValueError, match="b_lm of detector det0 are not finite"):
        pisco.litebird.add_convolved_sky_to_observations(obs, sky, bad, **small)
    with pytest.raises(TypeError, match="expected pisco.Beamsor or litebird_sim.SphericalHarmonics"):
        pisco.litebird.add_convolved_sky_to_observations(obs, sky, "beam.fits", **small)


def test_arguments_in_litebird_sims_shape(tmp_path):
    obs = observation(tmp_path, dtype=np.float32, seconds=60.0)
    nside = 64
    maps = hp.alm2map(smooth_sky_alm(128, seed=2, smoothing_fwhm=np.radians(2.0)), nside, lmax=128, pol=True)
    sky = pisco.Sky.from_maps(maps)
    beam = pisco.Beamsor.gaussian(np.radians(1.0), rho_max=np.radians(2.5))
    # A pisco.Sky in galactic coordinates (stated), one beam for all: into the float32 `tod`, added.
    obs.tod[:] = 1.0
    pisco.litebird.add_convolved_sky_to_observations(obs, sky, beam, coordinates=lbs.CoordinateSystem.Galactic,
                                                     backend="cpu")
    first = obs.tod.copy()
    assert first.dtype == np.float32 and np.all(np.isfinite(first)) and np.any(first != 1.0)
    # Dicts by channel and by detector name, and the observation's pointings passed explicitly.
    pointings, _ = obs.get_pointings("all")
    for skies, beams in (({"ch": sky}, {"ch": beam}), ({f"det{k}": sky for k in range(3)}, {"ch": beam})):
        obs.pisco[:] = 0
        pisco.litebird.add_convolved_sky_to_observations([obs], skies, beams, pointings=[pointings],
                                                         component="pisco", backend="cpu",
                                                         coordinates=lbs.CoordinateSystem.Galactic)
        assert np.allclose(obs.pisco, first - 1.0, rtol=1e-5, atol=1e-6)
    # The default beams: Gaussians of the detectors' fwhm_arcmin.
    obs.pisco[:] = 0
    pisco.litebird.add_convolved_sky_to_observations(obs, sky, component="pisco", backend="cpu",
                                                     coordinates=lbs.CoordinateSystem.Galactic)
    assert relative_rms(obs.pisco, first - 1.0) < 1e-3
    with pytest.raises(ValueError, match="keys do not match"):
        pisco.litebird.add_convolved_sky_to_observations(obs, {"other": sky}, beam, component="pisco")
    with pytest.raises(TypeError, match="sky: expected a pisco.Sky"):
        pisco.litebird.add_convolved_sky_to_observations(obs, "sky.fits", beam, component="pisco")


def test_unknown_coordinates_are_galactic_with_a_warning(tmp_path, caplog):
    obs = observation(tmp_path, seconds=10.0)
    sky = pisco.Sky(32)
    with caplog.at_level(logging.WARNING):
        pisco.litebird.add_convolved_sky_to_observations(obs, sky, component="pisco", backend="cpu")
    assert "assuming CoordinateSystem.Galactic" in caplog.text


@pytest.mark.parametrize("plate", ["ideal", "generic"])
def test_plates_match_litebird_sims_mueller_convolver(tmp_path, plate):
    """litebird_sim's IdealHWP turning at 46 rpm from 0.3 rad, each detector's mueller_hwp the ideal
    or the generic plate: litebird_sim's own function (MuellerConvolver, alpha = its HWP angle) and
    pisco.litebird on the same observation, I, Q, U sky and beams."""
    m0 = IDEAL if plate == "ideal" else GENERIC
    obs = compare(tmp_path, nside=256, ellipticity=1.0, hwp=lbs.IdealHWP(ang_speed_radpsec=HWP_SPEED,
                                                                         start_angle_rad=0.3), mueller_hwp=m0)
    assert obs.has_hwp
    rms = relative_rms(obs.pisco, obs.tod)
    per_detector = [relative_rms(obs.pisco[i], obs.tod[i]) for i in range(len(POL_ANGLES_DEG))]
    print(f"pisco.litebird vs litebird_sim MuellerConvolver, {plate} plate at 46 rpm: {obs.tod.shape[0]} detectors x "
          f"{obs.tod.shape[1]} samples, sky NSIDE 256 (lmax 512), FWHM 1 deg, polarization angles {POL_ANGLES_DEG} "
          f"deg: relative RMS {rms:.2e} (per detector {', '.join(f'{r:.2e}' for r in per_detector)})")
    assert rms <= 1e-4 and max(per_detector) <= 2e-4
    sky = lbs.HealpixMap(values=hp.alm2map(smooth_sky_alm(512, seed=5, smoothing_fwhm=np.radians(0.5)), 256,
                                           lmax=512, pol=True), nside=256, coordinates=lbs.CoordinateSystem.Galactic)
    # The plate in the beams (docs/changing.md): the same Gaussian times the plate's M(theta_k) at five
    # plate angles (M(theta) holds harmonics 0, 2 and 4 theta: exact), through plate_beams, normalized by
    # the Gaussian's own Omega~ (which keeps the plate's losses, as MuellerConvolver does), against
    # MuellerConvolver directly.
    fwhm = np.radians(FWHM_ARCMIN / 60.0)
    s = fwhm / np.sqrt(8 * np.log(2.0))

    def gauss(r, sigma):
        return np.exp(-r * r / (2 * s * s)) * np.eye(4)

    turning = [pisco.Beamsor.from_field(
        lambda r, sigma, k=k: gauss(r, sigma) @ np.array(pisco.rotated_mueller(m0, np.pi * k / 5)),
        2.5 * fwhm, fwhm / 20, f"plate at {k} pi / 5") for k in range(5)]
    omega = pisco.Beamsor.from_field(gauss, 2.5 * fwhm, fwhm / 20, "without the plate").omega_tilde
    obs.pisco2[:] = 0
    pisco.litebird.add_convolved_sky_to_observations(obs, sky, component="pisco2", backend="cpu", plate_beams=turning,
                                                     plate_beams_omega=omega)
    in_beams = relative_rms(obs.pisco2, obs.tod)
    print(f"  the plate in five plate beams (plate_beams) vs MuellerConvolver: relative RMS {in_beams:.2e}")
    assert in_beams <= 1e-4
    # The comparison tells the plate's conventions apart: the plate turning the other way (an explicit
    # `hwp`, which replaces the observation's) misses by O(1).
    obs.pisco[:] = 0
    pisco.litebird.add_convolved_sky_to_observations(obs, sky, component="pisco", backend="cpu",
                                                     hwp=lbs.IdealHWP(ang_speed_radpsec=-HWP_SPEED,
                                                                      start_angle_rad=-0.3))
    wrong = relative_rms(obs.pisco, obs.tod)
    print(f"  the plate turning the other way: relative RMS {wrong:.2f}")
    assert wrong > 0.1


def test_plate_arguments(tmp_path):
    """The plate's angle from an explicit HWP or the observation's, the detectors' mueller_hwp, the
    placement, and what is refused."""
    obs = observation(tmp_path, seconds=20.0)
    assert not obs.has_hwp
    sky = pisco.Sky.from_maps(hp.alm2map(smooth_sky_alm(128, seed=2, smoothing_fwhm=np.radians(2.0)), 64,
                                         lmax=128, pol=True))
    beam = pisco.Beamsor.gaussian(np.radians(1.0), rho_max=np.radians(2.5))
    galactic = lbs.CoordinateSystem.Galactic

    def run(target, **kwargs):
        target.pisco[:] = 0
        pisco.litebird.add_convolved_sky_to_observations(target, sky, beam, component="pisco", backend="cpu",
                                                         coordinates=galactic, **kwargs)
        return target.pisco.copy()

    plain = run(obs)
    hwp = lbs.IdealHWP(ang_speed_radpsec=HWP_SPEED, start_angle_rad=0.3)
    with_hwp = run(obs, hwp=hwp)
    assert relative_rms(with_hwp, plain) > 0.1
    # The same through PISCO-VK's engine: each detector's plate at gamma = pol_angle_rad, the angles
    # litebird_sim's (start_angle_rad + ang_speed_radpsec t), the gain 2 of pol_efficiency 1.
    h = 0.3 + HWP_SPEED * np.arange(obs.n_samples) / obs.sampling_rate_hz
    pointings, _ = obs.get_pointings("all")
    fp = pisco.FocalPlane()
    for k, angle in enumerate(POL_ANGLES_DEG):
        fp.add(f"det{k}", zeta=np.radians(angle), gain=2.0, hwp=pisco.HalfWavePlate(gamma=np.radians(angle)))
    from litebird_sim.coordinates import rotate_coordinates_e2g

    with pisco.Engine(sky, beam, fp, backend="cpu") as engine:
        for k in range(len(POL_ANGLES_DEG)):
            p = rotate_coordinates_e2g(pointings[k])
            tod = engine.convolve(k, *(np.ascontiguousarray(p[:, c]) for c in range(3)), hwp_angle=h)
            assert relative_rms(with_hwp[k], tod) < 1e-9
    # The observation's own plate (set before the observations), and each detector's mueller_hwp.
    own = observation(tmp_path, seconds=20.0, hwp=hwp)
    assert np.allclose(run(own), with_hwp, rtol=0, atol=1e-10 * np.max(np.abs(with_hwp)))
    leaky = observation(tmp_path, seconds=20.0, hwp=hwp, mueller_hwp=GENERIC)
    generic = run(leaky)
    assert relative_rms(generic, with_hwp) > 1e-3
    assert relative_rms(run(leaky, hwp_placement="detector"), generic) < 1e-12  # a round beam commutes
    with pytest.raises(ValueError, match="hwp_placement: expected 'aperture' or 'detector'"):
        run(leaky, hwp_placement="sky")
    # Refused: Mueller matrices that are not one finite 4x4 matrix per detector, Jones matrices.
    leaky.mueller_hwp = np.array([np.diag([1.0, 1.0, -1.0, np.nan])] * 3)
    with pytest.raises(ValueError, match="mueller_hwp is not finite"):
        run(leaky)
    leaky.mueller_hwp = np.array([-IDEAL] * 3)  # M00 = -1: not a passive element
    with pytest.raises(ValueError, match=r"^detector .*: mueller_hwp: M00 = -1 \(T to T\) is not positive"):
        run(leaky)
    leaky.mueller_hwp = np.array([{"0f": IDEAL}] * 3, dtype=object)
    with pytest.raises(NotImplementedError, match="harmonic expansion"):
        run(leaky)
    leaky.mueller_hwp = np.array([None] * 3, dtype=object)
    leaky.jones_hwp = np.array([np.eye(2)] * 3)
    with pytest.raises(NotImplementedError, match="Jones matrix"):
        run(leaky)


# litebird_sim's MuellerConvolver and an off-axis beam through a plate (docs/python.md, "litebird_sim's
# Mueller convolver"): MuellerConvolver turns the beam's spin -2 coefficients into spin +2 ones by
# relabelling them, P+_eff[l, m] = C21 e^{4i alpha} P-[l, m + 4], which keeps each coefficient's l and is
# exact only at m = -2 (a beam on its axis has its polarization there; one off its axis at every m).
# mueller_reference.ExactMuellerConvolver makes the same effective beams exactly, by turning the beam's
# field in real space; PISCO-VK matches it, MuellerConvolver does not.

def test_mueller_convolvers_relabelling_is_exact_only_at_m_minus_2():
    """The effective spin +2 beam of an ideal plate at alpha = 0, MuellerConvolver's against the exact
    one, m by m, for a beam 1 deg off its axis: equal at m = -2, apart at 2e-4 and more elsewhere."""
    from mueller_reference import effective_beams, pplus_by_m

    ls, lb, mm = 512, 768, 12
    blm = offset_elliptical_blm(lb, mm, np.radians(1.0), 1.5, np.radians(25.0), psi_pol=0.0, cross_polar_leakage=0.02,
                                offset=np.radians(1.0), offset_angle=np.radians(40.0))
    theirs_raw, exact_raw = effective_beams(blm, lb, mm, ls, IDEAL)
    theirs = pplus_by_m(theirs_raw[0][1:3], ls, mm + 4)
    exact = pplus_by_m(exact_raw[0][1:3], ls, mm + 4)
    total = sum(np.sum(np.abs(v) ** 2) for v in exact.values())
    diff = {m: np.sqrt(np.sum(np.abs(theirs[m] - exact[m]) ** 2) / np.sum(np.abs(exact[m]) ** 2)) for m in exact
            if np.sum(np.abs(exact[m]) ** 2) > 1e-6 * total}
    print("MuellerConvolver's effective spin +2 beam against the exact one, beam 1 deg off its axis, by m: "
          + ", ".join(f"{m:+d}: {d:.1e}" for m, d in sorted(diff.items())))
    assert diff[-2] <= 1e-6
    assert min(d for m, d in diff.items() if m != -2) >= 2e-4


def test_an_off_axis_beam_through_a_plate_matches_the_exact_reference():
    """A b_lm beam 1 deg off its axis (FWHM 1 deg, ellipticity 1.5, cross-polar leakage) behind an ideal plate, on a
    sky with a monopole and a dipole, samples within 3 deg of both poles and over the sphere: PISCO-VK
    against the exact reference within 3e-4 of the TOD's RMS; MuellerConvolver's own difference from
    the reference is its relabelling (above)."""
    from mueller_reference import exact_conv, mueller_conv, pisco_tod, ptg_array
    from pisco._blm import resize_blm

    ls, lb, mm, nside = 512, 768, 12, 256
    alm = smooth_sky_alm(ls, seed=5, smoothing_fwhm=np.radians(1.0))
    alm[0, hp.Alm.getidx(ls, 0, 0)] = 3.0 * np.sqrt(4 * np.pi)
    alm[0, hp.Alm.getidx(ls, 1, 0)] = 0.5
    sky = pisco.Sky.from_maps(hp.alm2map(alm, nside, lmax=ls, pol=True))
    rng = np.random.default_rng(4)
    n = 1500
    theta = np.arccos(rng.uniform(-1, 1, n))
    theta[:150] = rng.uniform(0, np.radians(3), 150)
    theta[150:300] = np.pi - rng.uniform(0, np.radians(3), 150)
    phi, psi, alpha = rng.uniform(0, 2 * np.pi, n), rng.uniform(-np.pi, np.pi, n), rng.uniform(0, 2 * np.pi, n)
    ptg = ptg_array(theta, phi, psi)
    blm = offset_elliptical_blm(lb, mm, np.radians(1.0), 1.5, np.radians(25.0), psi_pol=0.0, cross_polar_leakage=0.02,
                                offset=np.radians(1.0), offset_angle=np.radians(40.0))
    exact, imag = exact_conv(alm, blm, lb, mm, ls, IDEAL, ptg, alpha)
    theirs = mueller_conv(alm, resize_blm(blm, lb, mm, ls, mm), ls, mm, IDEAL, ptg, alpha)
    ours, _ = pisco_tod(sky, blm, lb, mm, theta, phi, psi, alpha=alpha, mueller=IDEAL, rho_max_deg=5.0)
    scale = np.sqrt(np.mean((exact - exact.mean()) ** 2))
    mine = np.abs(ours - exact) / scale
    theirs_err = np.abs(theirs - exact) / scale
    print(f"off-axis b_lm beam behind an ideal plate, NSIDE {nside}: PISCO-VK vs the exact reference: RMS "
          f"{np.sqrt(np.mean(mine ** 2)):.2e}, worst {mine.max():.2e} of the TOD's RMS; MuellerConvolver vs the "
          f"reference: RMS {np.sqrt(np.mean(theirs_err ** 2)):.2e}, worst {theirs_err.max():.2e}; the reference's "
          f"imaginary residue {imag:.1e}")
    assert imag <= 1e-10
    assert np.sqrt(np.mean(mine ** 2)) <= 1e-4 and mine.max() <= 3e-4
    assert np.sqrt(np.mean(theirs_err ** 2)) >= 3 * np.sqrt(np.mean(mine ** 2))


def test_a_plate_with_intensity_leakage_passes_the_monopole_which_mueller_convolver_loses():
    """A sky with I = 1 everywhere, a round 1 deg beam on its axis, the generic plate (M_QI, M_UI not
    zero): the detector reads M(alpha)'s (I + Q) row applied to (1, 0, 0, 0), which turns with the plate.
    PISCO-VK and the exact reference follow it; litebird_sim 0.18's MuellerConvolver builds its effective
    T beam from the spin +-2 coefficients relabelled with the same l, so it has nothing at l = 0 and 1
    and its TOD does not turn."""
    from mueller_reference import exact_conv, mueller_conv, pisco_tod, ptg_array
    from conftest import gaussian_blm
    from pisco._blm import resize_blm

    ls, lb, nside = 512, 768, 256
    slm = np.zeros((3, hp.Alm.getsize(ls)), complex)
    slm[0, 0] = np.sqrt(4 * np.pi)
    sky = pisco.Sky.from_maps(hp.alm2map(slm, nside, lmax=ls, pol=True))
    rng = np.random.default_rng(6)
    n = 600
    theta = np.arccos(rng.uniform(-1, 1, n))
    theta[:60] = rng.uniform(0, np.radians(2), 60)
    phi, psi, alpha = rng.uniform(0, 2 * np.pi, n), rng.uniform(-np.pi, np.pi, n), rng.uniform(0, 2 * np.pi, n)
    ptg = ptg_array(theta, phi, psi)
    g = gaussian_blm(lb, np.radians(1.0))

    def turn(a):
        c, s = np.cos(2 * a), np.sin(2 * a)
        return np.array([[1, 0, 0, 0], [0, c, s, 0], [0, -s, c, 0], [0, 0, 0, 1]])

    expected = np.array([(turn(-a) @ GENERIC @ turn(a))[0, 0] + (turn(-a) @ GENERIC @ turn(a))[1, 0] for a in alpha])
    exact, _ = exact_conv(slm, g, lb, 2, ls, GENERIC, ptg, alpha)
    ours, _ = pisco_tod(sky, g, lb, 2, theta, phi, psi, alpha=alpha, mueller=GENERIC)
    theirs = mueller_conv(slm, resize_blm(g, lb, 2, ls, 2), ls, 2, GENERIC, ptg, alpha)
    print(f"I = 1 sky, generic plate: the plate's leakage turns the TOD by {expected.std():.2e} (std over alpha); "
          f"PISCO-VK {ours.std():.2e} and within {np.abs(ours - expected).max():.1e} of it, the exact reference "
          f"within {np.abs(exact - expected).max():.1e}, MuellerConvolver {theirs.std():.1e} (litebird_sim "
          f"{lbs.__version__})")
    assert expected.std() > 1e-2
    assert np.abs(ours - expected).max() <= 1e-5
    assert np.abs(exact - expected).max() <= 1e-5
    if lbs.__version__.startswith("0.18"):  # the version this was found in
        assert theirs.std() <= 1e-6 * expected.std()


def test_plate_beams_of_an_ideal_plate_are_the_plate_model(tmp_path):
    """plate_beams (docs/changing.md): every detector's beam given as five beams with an ideal plate in them
    (a 1 deg Gaussian times the plate's Mueller matrix at plate angles k pi / 5 from the detector's axis),
    under litebird_sim's IdealHWP turning at 46 rpm from 0.3 rad, detectors at three polarization angles
    and offsets, against the same Gaussian behind the adapter's ideal plate model (which
    test_plates_match_litebird_sims_mueller_convolver holds against litebird_sim's MuellerConvolver):
    the same TOD to rounding. A dict by channel name gives the same; without plate angles it is refused."""
    hwp = lbs.IdealHWP(ang_speed_radpsec=HWP_SPEED, start_angle_rad=0.3)
    obs = observation(tmp_path, seconds=120.0, hwp=hwp)
    sky = pisco.Sky.from_maps(hp.alm2map(smooth_sky_alm(256, seed=4, smoothing_fwhm=np.radians(0.5)), 128,
                                         lmax=256, pol=True))
    fwhm = np.radians(FWHM_ARCMIN / 60.0)
    s = fwhm / np.sqrt(8 * np.log(2.0))

    def gauss(r, sigma):
        g = np.exp(-r * r / (2 * s * s))
        return np.diag([g, g, g, g])

    plain = pisco.Beamsor.from_field(gauss, 2.5 * fwhm, fwhm / 16, "gaussian")
    turning = []
    for k in range(5):
        m = np.array(pisco.rotated_mueller(pisco.ideal_hwp_mueller(), np.pi * k / 5))
        turning.append(pisco.Beamsor.from_field(lambda r, sigma, m=m: gauss(r, sigma) @ m, 2.5 * fwhm, fwhm / 16,
                                                f"plate {k}"))
    galactic = lbs.CoordinateSystem.Galactic
    for name in ("pisco", "pisco2", "tod2"):
        getattr(obs, name)[:] = 0
    pisco.litebird.add_convolved_sky_to_observations(obs, sky, plain, hwp=hwp, component="pisco", backend="cpu",
                                                     coordinates=galactic)
    pisco.litebird.add_convolved_sky_to_observations(obs, sky, plain, hwp=hwp, component="pisco2", backend="cpu",
                                                     coordinates=galactic, plate_beams=turning)
    pisco.litebird.add_convolved_sky_to_observations(obs, sky, plain, hwp=hwp, component="tod2", backend="cpu",
                                                     coordinates=galactic, plate_beams={"ch": turning})
    rms = relative_rms(obs.pisco2, obs.pisco)
    print(f"litebird: plate_beams (an ideal plate as five beams) vs the plate model: relative RMS {rms:.2e}")
    assert rms <= 1e-12
    assert np.array_equal(obs.tod2, obs.pisco2)
    plateless = observation(tmp_path / "plateless", seconds=10.0)
    with pytest.raises(ValueError, match="beams turn with the plate, but the observation has no plate angles"):
        pisco.litebird.add_convolved_sky_to_observations(plateless, sky, plain, component="pisco", backend="cpu",
                                                         coordinates=galactic, plate_beams=turning)
    with pytest.raises(TypeError, match="expected a list of two or more pisco.Beamsor"):
        pisco.litebird.add_convolved_sky_to_observations(obs, sky, plain, hwp=hwp, component="pisco", backend="cpu",
                                                         coordinates=galactic, plate_beams=[plain])


@pytest.mark.parametrize("clock", ["float", "astropy"])
def test_sources_follow_the_observations_clock(tmp_path, clock):
    """sources (docs/sources.md) in litebird_sim: a source whose track is detector 0's own line of sight
    (galactic, as the sky's frame; a point every other sample, the clock the observation's float times or,
    for an astropy start_time, Unix seconds) sits on that detector's beam axis all along: its TOD is
    the beam's peak response at every sample (to the great circles between the points), which it would
    leave within a second of a wrong clock (the spin moves the line of sight 3 deg a second); the other
    detectors' TOD is the engine's own add_sources on their pointings."""
    import astropy.time
    from litebird_sim.coordinates import rotate_coordinates_e2g

    if clock == "astropy":
        obs = observation(tmp_path, seconds=60.0, start_time=astropy.time.Time("2030-04-01T00:00:00", scale="tdb"))
        times = obs.get_times(astropy_times=True).unix
    else:
        obs = observation(tmp_path, seconds=60.0)
        times = obs.get_times()
    pointings = [rotate_coordinates_e2g(obs.get_pointings(i, pointings_dtype=np.float64)[0]) for i in range(3)]
    step = np.unique(np.r_[0 : len(times) : 2, len(times) - 1])
    track = pisco.SourceTrack("riding", list(times[step]), list(pointings[0][step, 0]), list(pointings[0][step, 1]),
                              [1e-5] * len(times[step]))
    obs.pisco[:] = 0
    sky = pisco.Sky(64)
    beam = pisco.Beamsor.gaussian(np.radians(FWHM_ARCMIN / 60.0), rho_max=2.5 * np.radians(FWHM_ARCMIN / 60.0))
    galactic = lbs.CoordinateSystem.Galactic
    pisco.litebird.add_convolved_sky_to_observations(obs, sky, beam, component="pisco", backend="cpu",
                                                     coordinates=galactic, sources=[track])
    last = len(times)
    riding = obs.pisco[0][:last]
    print(f"litebird sources ({clock} clock): detector 0's TOD from {riding.min():.6e} to {riding.max():.6e}")
    assert riding.max() > 0 and riding.min() > 0.999 * riding.max()
    fp = pisco.FocalPlane()
    for i in range(3):
        eta = float(obs.pol_efficiency[i]) if hasattr(obs, "pol_efficiency") else 1.0
        epsilon = (1.0 - eta) / (1.0 + eta)
        fp.add(str(obs.name[i]), zeta=float(obs.pol_angle_rad[i]), epsilon=epsilon, gain=2.0 / (1.0 + epsilon))
    with pisco.Engine(sky, beam, fp, backend="cpu") as engine:
        for i in (1, 2):
            p = pointings[i][:last]
            direct = engine.add_sources(i, times[:last], [track], p[:, 0].copy(), p[:, 1].copy(), p[:, 2].copy())
            assert np.array_equal(obs.pisco[i][:last], direct)
    with pytest.raises(TypeError, match=r"sources\[0\]: expected a pisco.SourceTrack, got str"):
        pisco.litebird.add_convolved_sky_to_observations(obs, sky, beam, component="pisco", backend="cpu",
                                                         coordinates=galactic, sources=["jupiter"])
