"""pisco.toast.PixelConvolve in TOAST 3 (installed from PyPI): against TOAST's own SimTotalconvolve
(ducc0's total convolution) on the same observation, band-limited sky and Gaussian beam; in a TOAST
pipeline with TOAST's binned map-maker; the focal-plane mapping, views, units and plates."""

import os
from datetime import datetime, timedelta, timezone

os.environ.setdefault("TOAST_LOGLEVEL", "WARNING")

import healpy as hp  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402
from astropy import units as u  # noqa: E402

import toast  # noqa: E402
import toast.ops  # noqa: E402
from toast.instrument import GroundSite, SpaceSite, Telescope  # noqa: E402
from toast.instrument_sim import fake_hexagon_focalplane  # noqa: E402
from toast.intervals import IntervalList  # noqa: E402
from toast.schedule import GroundScan, GroundSchedule  # noqa: E402
from toast.schedule_sim_satellite import create_satellite_schedule  # noqa: E402

import pisco  # noqa: E402
import pisco.toast  # noqa: E402
from conftest import gaussian_blm, relative_rms, smooth_sky_alm  # noqa: E402

FWHM = np.radians(1.0)
EPSILON = 0.05


def focalplane(epsilon=EPSILON, fwhm=FWHM, n_pix=7):
    fp = fake_hexagon_focalplane(n_pix=n_pix, width=5 * u.deg, sample_rate=10 * u.Hz, epsilon=epsilon,
                                 fwhm=fwhm * u.rad)
    return fp


def satellite_data(fp, seconds=600.0):
    tele = Telescope("satellite", focalplane=fp, site=SpaceSite("L2"))
    schedule = create_satellite_schedule(
        prefix="sat_", mission_start=datetime(2023, 2, 23, tzinfo=timezone.utc),
        observation_time=seconds * u.s, gap_time=0 * u.s, num_observations=1,
        prec_period=10 * u.min, spin_period=2 * u.min)
    data = toast.Data(toast.mpi.Comm())
    toast.ops.SimSatellite(name="sim_satellite", telescope=tele, schedule=schedule, hwp_angle=None,
                           spin_angle=30 * u.deg, prec_angle=65 * u.deg, detset_key="pixel").apply(data)
    return data


def ground_data(fp, seconds=1800.0):
    site = GroundSite("atacama", "-22:57:30", "-67:47:10", 5200.0 * u.meter)
    tele = Telescope("ground", focalplane=fp, site=site)
    start = datetime(2020, 1, 1, 3, 0, 0, tzinfo=timezone.utc)
    scan = GroundScan(name="field", start=start, stop=start + timedelta(seconds=seconds), boresight_angle=0 * u.deg,
                      az_min=30 * u.deg, az_max=70 * u.deg, el=50 * u.deg)
    schedule = GroundSchedule(scans=[scan], site_name=site.name, telescope_name=tele.name,
                              site_lat=site.earthloc.lat, site_lon=site.earthloc.lon, site_alt=site.earthloc.height)
    data = toast.Data(toast.mpi.Comm())
    toast.ops.SimGround(name="sim_ground", telescope=tele, schedule=schedule, detset_key="pixel", hwp_angle=None,
                        use_ephem=True, scan_rate_az=1.0 * u.deg / u.s).apply(data)
    return data


class TotalconvolveForCurrentDucc0(toast.ops.SimTotalconvolve):
    """TOAST's SimTotalconvolve with two repairs for the ducc0 that PyPI installs beside it; its
    conventions (psi - psi_pol + pi, the factor 1/2, the calibration 2 / (1 + epsilon)) are untouched.

    - ducc0's ConvolverPlan.interpol takes phi in [0, 2 pi) and psi in [-2 pi, 2 pi]: TOAST hands it
      phi in (-pi, pi] and psi up to 3 pi, and ducc0 stops ("phi out of range"). Wrapped here.
    - ConvolverPlan.getPlane fills the planes it is given; TOAST calls it once per Stokes component on
      the same planes, so that only the last component (B) would remain. Summed here.
    """

    def get_buffer(self, theta, phi, psi, det, verbose):
        pnt = super().get_buffer(theta, phi, psi, det, verbose)
        pnt[:, 1] = np.mod(pnt[:, 1], 2 * np.pi)
        pnt[:, 2] = np.mod(pnt[:, 2], 2 * np.pi)
        return pnt

    def conv_and_interpol_serial(self, skycomp, beamcomp, lmax, mmax, pnt, nthreads, t_conv, t_inter):
        import ducc0.totalconvolve

        plan = ducc0.totalconvolve.ConvolverPlan(lmax=lmax, kmax=mmax, sigma=self.oversampling_factor,
                                                 epsilon=self.epsilon, nthreads=nthreads)
        cube = np.zeros((plan.Npsi(), plan.Ntheta(), plan.Nphi()))
        planes = np.empty((2, plan.Ntheta(), plan.Nphi()))
        for comp in range(skycomp.shape[0]):
            plan.getPlane(skycomp[comp], beamcomp[comp], 0, planes[0:1])
            cube[0:1] += planes[0:1]
            for m in range(1, mmax + 1):
                plan.getPlane(skycomp[comp], beamcomp[comp], m, planes)
                cube[2 * m - 1 : 2 * m + 1] += planes
        plan.prepPsi(cube)
        result = np.empty(pnt.shape[0])
        plan.interpol(cube, 0, 0, pnt[:, 0], pnt[:, 1], pnt[:, 2], result)
        return result


def toast_totalconvolve(data, fp, alm, lmax, tmp_path, det_data):
    """TOAST's own beam convolution of the sky `alm` with the Gaussian beam, into `det_data`."""
    sky_file = str(tmp_path / "sky_alm.fits")
    hp.write_alm(sky_file, alm, lmax=lmax, overwrite=True)
    # psi_pol: the polarization direction in the beam frame. TOAST's SimTotalconvolve reads it from the
    # column `pol_angle` (while testing for `psi_pol`): give it that column. The beam of a B detector,
    # in its beam frame, is polarized at 90 deg (TOAST's own test beams flip Q for B detectors).
    fp.detector_data["pol_angle"] = fp.detector_data["psi_pol"]
    beam_files = {}
    for name, psi_pol in zip(fp.detector_data["name"], fp.detector_data["psi_pol"]):
        angle = float(u.Quantity(psi_pol).to_value(u.deg))
        assert angle in (0.0, 90.0)
        path = str(tmp_path / f"beam_{int(angle)}.fits")
        if not os.path.exists(path):
            hp.write_alm(path, gaussian_blm(lmax, FWHM, EPSILON, sign=1.0 if angle == 0 else -1.0), lmax=lmax,
                         mmax_in=2, overwrite=True)
        beam_files[str(name)] = path
    op = TotalconvolveForCurrentDucc0(
        comm=None, detector_pointing=toast.ops.PointingDetectorSimple(quats="tc_quats"), sky_file=sky_file,
        beam_file_dict=beam_files, sky_file_dict={}, dxx=False, det_data=det_data, fwhm=0 * u.rad, lmax=lmax,
        beammmax=2, epsilon=1e-7)
    op.apply(data)


def test_pixel_convolve_matches_toast_total_convolution(tmp_path):
    nside, lmax = 256, 512
    fp = focalplane()
    data = satellite_data(fp)
    alm = smooth_sky_alm(lmax, seed=3, smoothing_fwhm=np.radians(0.5))
    sky = pisco.Sky.from_maps(hp.alm2map(alm, nside, lmax=lmax, pol=True), units="K")
    toast_totalconvolve(data, fp, alm, lmax, tmp_path, "totalconvolve")
    pisco.toast.PixelConvolve(sky=sky, det_data="pisco", backend="cpu").apply(data)
    ob = data.obs[0]
    dets = list(ob.local_detectors)
    reference = np.array([ob.detdata["totalconvolve"][d] for d in dets])
    ours = np.array([ob.detdata["pisco"][d] for d in dets])
    rms = relative_rms(ours, reference)
    worst = max(relative_rms(ours[i], reference[i]) for i in range(len(dets)))
    print(f"PixelConvolve vs TOAST SimTotalconvolve: {len(dets)} detectors x {ours.shape[1]} samples, sky NSIDE "
          f"{nside} (lmax {lmax}), FWHM 1 deg, pol_leakage {EPSILON}: relative RMS {rms:.2e} (worst detector {worst:.2e})")
    assert rms <= 1e-4 and worst <= 2e-4
    # The polarization alone, held to its own RMS: the pair differences (detectors A and B of a pixel
    # are neighbours in the table).
    assert [d[-5] for d in dets[:2]] == ["A", "B"]
    pol = relative_rms(ours[0::2] - ours[1::2], reference[0::2] - reference[1::2])
    print(f"pair differences (polarization): relative RMS {pol:.2e}")
    assert pol <= 1e-3


def binned_map(data, nside, det_data, tmp_path, name):
    """TOAST's own binned map-maker (BinMap) of det_data: (I, Q, U) maps, NSIDE nside, RING; hits."""
    detpointing = toast.ops.PointingDetectorSimple(quats="bin_quats")
    pixels = toast.ops.PixelsHealpix(nside=nside, nest=False, detector_pointing=detpointing, pixels="bin_pixels")
    weights = toast.ops.StokesWeights(mode="IQU", detector_pointing=detpointing, weights="bin_weights",
                                      hwp_angle=None)
    noise = toast.ops.DefaultNoiseModel(noise_model="bin_noise")
    noise.apply(data)
    cov = toast.ops.CovarianceAndHits(pixel_dist="bin_dist", pixel_pointing=pixels, stokes_weights=weights,
                                      noise_model="bin_noise", rcond_threshold=1e-3, covariance="bin_cov",
                                      hits="bin_hits", rcond="bin_rcond")
    cov.apply(data)
    binner = toast.ops.BinMap(pixel_dist="bin_dist", covariance="bin_cov", det_data=det_data, pixel_pointing=pixels,
                              stokes_weights=weights, noise_model="bin_noise", binned="bin_map")
    binner.apply(data)
    path = str(tmp_path / f"{name}_map.fits")
    data["bin_map"].write(path)
    hits = str(tmp_path / f"{name}_hits.fits")
    data["bin_hits"].write(hits)
    return np.array(hp.read_map(path, field=None, nest=False)), np.array(hp.read_map(hits, nest=False))


def test_pipeline_ground_scan_binned_map(tmp_path):
    """Simulate a ground observation, convolve with PixelConvolve, bin with TOAST: the map is the
    input sky smoothed by the beam, in I, Q and U."""
    nside_sky, lmax, nside_map = 256, 512, 64
    fp = focalplane(epsilon=0.0)
    data = ground_data(fp)
    alm = smooth_sky_alm(lmax, seed=5, smoothing_fwhm=np.radians(2.0))
    sky = pisco.Sky.from_maps(hp.alm2map(alm, nside_sky, lmax=lmax, pol=True), units="K")
    pipeline = toast.ops.Pipeline(operators=[pisco.toast.PixelConvolve(sky=sky, backend="cpu")])
    pipeline.apply(data)
    maps, hits = binned_map(data, nside_map, toast.observation.default_values.det_data, tmp_path, "ground")
    smoothed = hp.alm2map(hp.smoothalm(alm, fwhm=FWHM, pol=True, inplace=False), nside_map, lmax=lmax, pol=True)
    # Pixels the map-maker solved (it leaves those below its rcond threshold at 0), well hit.
    seen = (hits > 50) & (maps[0] != 0) & np.all(maps != hp.UNSEEN, axis=0)
    assert seen.sum() > 300
    figures = []
    for k, stokes in enumerate("IQU"):
        figures.append(relative_rms(maps[k][seen], smoothed[k][seen]))
    print(f"ground scan, TOAST BinMap at NSIDE {nside_map} over {seen.sum()} pixels: relative RMS of map - smoothed "
          f"input: I {figures[0]:.2e}, Q {figures[1]:.2e}, U {figures[2]:.2e}")
    # The map is the sky averaged over each NSIDE 64 pixel's samples, not at its centre: a few percent.
    # A polarization convention error would leave Q and U at the level of their own RMS.
    assert figures[0] < 0.04 and figures[1] < 0.08 and figures[2] < 0.08


def test_focal_plane_mapping_matches_the_file_reader(tmp_path):
    import h5py

    fp = focalplane(epsilon=0.1)
    path = str(tmp_path / "focalplane.h5")
    with h5py.File(path, "w") as f:
        fp.save_hdf5(f)
    from_file = pisco.FocalPlane.read_toast(path)
    from_table = pisco.FocalPlane.from_toast(fp)
    assert from_file.names == from_table.names == [str(n) for n in fp.detector_data["name"]]
    for a, b in zip(from_file.detectors, from_table.detectors):
        assert a.zeta == pytest.approx(b.zeta, abs=1e-15) and a.epsilon == pytest.approx(b.epsilon, abs=1e-15)
        assert a.gain == pytest.approx(2 / 1.1, abs=1e-15) and b.gain == pytest.approx(2 / 1.1, abs=1e-15)
        assert np.allclose(a.offset, b.offset, atol=1e-15) or np.allclose(a.offset, -b.offset, atol=1e-15)
    assert pisco.FocalPlane.from_toast(path).names == from_file.names
    fwhm = pisco.read_toast_focal_plane(path)[1]
    assert np.allclose(fwhm, FWHM)


def test_views_units_zero_and_accumulate():
    fp = focalplane(n_pix=1)
    data = satellite_data(fp, seconds=60.0)
    ob = data.obs[0]
    n = ob.n_local_samples
    ob.intervals["first_half"] = IntervalList(ob.shared["times"], samplespans=[(0, n // 2)])
    sky = pisco.Sky.from_maps(hp.alm2map(smooth_sky_alm(128, 1, np.radians(2)), 64, lmax=128, pol=True),
                              units="uK_CMB")
    beam = pisco.Beamsor.gaussian(FWHM, rho_max=2.5 * FWHM)
    full = pisco.toast.PixelConvolve(sky=sky, beam=beam, det_data="full", det_data_units=u.uK, backend="cpu")
    full.apply(data)
    half = pisco.toast.PixelConvolve(sky=sky, beam=beam, det_data="half", det_data_units=u.uK, view="first_half",
                                     backend="cpu")
    half.apply(data)
    kelvin = pisco.toast.PixelConvolve(sky=sky, beam=beam, det_data="kelvin", det_data_units=u.K, backend="cpu")
    kelvin.apply(data)
    by_name = pisco.toast.PixelConvolve(sky=sky, beams={d: beam for d in ob.local_detectors}, det_data="by_name",
                                        det_data_units=u.uK, backend="cpu")
    by_name.apply(data)
    for det in ob.local_detectors:
        f, h, k = ob.detdata["full"][det], ob.detdata["half"][det], ob.detdata["kelvin"][det]
        assert np.any(f != 0)
        assert np.array_equal(h[: n // 2], f[: n // 2]) and not np.any(h[n // 2:])
        assert np.allclose(k, 1e-6 * f, rtol=1e-12, atol=0)
        assert np.array_equal(ob.detdata["by_name"][det], f)
    # Adding by default, overwriting with zero=True.
    full.apply(data)
    det = ob.local_detectors[0]
    twice = ob.detdata["full"][det].copy()
    pisco.toast.PixelConvolve(sky=sky, beam=beam, det_data="full", det_data_units=u.uK, zero=True,
                              backend="cpu").apply(data)
    assert np.allclose(twice, 2 * ob.detdata["full"][det], rtol=1e-14)
    req, prov = full.requires(), full.provides()
    assert "boresight_radec" in req["shared"] and "full" in prov["detdata"]


def test_plates_and_missing_inputs_raise():
    fp = focalplane(n_pix=1)
    data = satellite_data(fp, seconds=10.0)
    sky = pisco.Sky(16)
    beam = pisco.Beamsor.gaussian(FWHM)
    ob = data.obs[0]
    ob.shared.create_column("hwp_angle", (ob.n_local_samples,))
    with pytest.raises(NotImplementedError, match="half-wave plate angle 'hwp_angle'"):
        pisco.toast.PixelConvolve(sky=sky, beam=beam, backend="cpu").apply(data)
    pisco.toast.PixelConvolve(sky=sky, beam=beam, hwp_angle=None, backend="cpu").apply(data)
    with pytest.raises(RuntimeError, match="give sky"):
        pisco.toast.PixelConvolve(beam=beam, hwp_angle=None).apply(data)
    with pytest.raises(RuntimeError, match="no shared 'nothing'"):
        pisco.toast.PixelConvolve(sky=sky, beam=beam, hwp_angle=None, boresight="nothing").apply(data)
    with pytest.raises(Exception, match="beams"):
        pisco.toast.PixelConvolve(sky=sky, beams={"x": "not a beam"})
