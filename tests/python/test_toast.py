"""pisco.toast.PixelConvolve in TOAST 3 (installed from PyPI): against TOAST's own SimTotalconvolve
(ducc0's total convolution) on the same observation, band-limited sky and Gaussian beam; through a
half-wave plate against TOAST's own plate model (its StokesWeights with hwp_angle, and its
SimTotalconvolve's); in a TOAST pipeline with TOAST's binned map-maker; the focal-plane mapping,
views, units and plate options."""

import os
import time
from datetime import datetime, timedelta, timezone

os.environ.setdefault("TOAST_LOGLEVEL", "WARNING")

import healpy as hp  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402
from astropy import units as u  # noqa: E402

import toast  # noqa: E402
import toast.ops  # noqa: E402
import toast.qarray as qa  # noqa: E402
import traitlets  # noqa: E402
from toast.instrument import GroundSite, SpaceSite, Telescope  # noqa: E402
from toast.instrument_sim import fake_hexagon_focalplane  # noqa: E402
from toast.intervals import IntervalList  # noqa: E402
from toast.schedule import GroundScan, GroundSchedule  # noqa: E402
from toast.schedule_sim_satellite import create_satellite_schedule  # noqa: E402

import pisco  # noqa: E402
import pisco.toast  # noqa: E402
from conftest import assert_everywhere, gaussian_blm, offset_elliptical_blm, relative_rms, smooth_sky_alm  # noqa: E402

FWHM = np.radians(1.0)
EPSILON = 0.05


def focalplane(epsilon=EPSILON, fwhm=FWHM, n_pix=7):
    fp = fake_hexagon_focalplane(n_pix=n_pix, width=5 * u.deg, sample_rate=10 * u.Hz, epsilon=epsilon,
                                 fwhm=fwhm * u.rad)
    return fp


def turned_focalplane(fp, step):
    """TOAST's focal plane with the detectors of pixel k (both of a pair) turned by k step about their
    lines of sight (gamma and quat together, in TOAST's own xi, eta, gamma), so that a plate's 4 gamma
    term is not a multiple of 180 deg (tools/toast_pointing.py --gamma-step)."""
    from toast.instrument import Focalplane
    from toast.instrument_coords import quat_to_xieta, xieta_to_quat

    table = fp.detector_data.copy()
    for col in ("pol_angle", "pol_efficiency"):
        if col in table.colnames:
            table.remove_column(col)
    pixels = list(dict.fromkeys(str(x) for x in table["pixel"]))
    for row in table:
        turn = pixels.index(str(row["pixel"])) * step
        xi, eta, gamma = quat_to_xieta(np.array(row["quat"], dtype=np.float64))
        row["quat"] = xieta_to_quat(xi, eta, gamma + turn)
        row["gamma"] = (u.Quantity(row["gamma"]).to_value(u.rad) + turn) * u.rad
    return Focalplane(detector_data=table, sample_rate=fp.sample_rate, field_of_view=fp.field_of_view)


def satellite_data(fp, seconds=600.0, hwp_rpm=None, across_poles=False):
    """TOAST's simulated satellite. across_poles: at the March equinox, whose anti-sun direction lies on
    the celestial equator, with the boresight 88 deg from a spin axis 3 deg from it: nearly great circles
    through both poles (the boresight passes within 0.25 deg of each; 600 of 6,000 samples within 10 deg)."""
    tele = Telescope("satellite", focalplane=fp, site=SpaceSite("L2"))
    start = datetime(2023, 3, 20, 21, 24, tzinfo=timezone.utc) if across_poles else datetime(2023, 2, 23, tzinfo=timezone.utc)
    schedule = create_satellite_schedule(
        prefix="sat_", mission_start=start,
        observation_time=seconds * u.s, gap_time=0 * u.s, num_observations=1,
        prec_period=10 * u.min, spin_period=2 * u.min)
    data = toast.Data(toast.mpi.Comm())
    plate = dict(hwp_angle="hwp_angle", hwp_rpm=hwp_rpm) if hwp_rpm is not None else dict(hwp_angle=None)
    angles = dict(spin_angle=88 * u.deg, prec_angle=3 * u.deg) if across_poles else dict(spin_angle=30 * u.deg,
                                                                                          prec_angle=65 * u.deg)
    toast.ops.SimSatellite(name="sim_satellite", telescope=tele, schedule=schedule, detset_key="pixel", **angles,
                           **plate).apply(data)
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


def pair_beam_files(fp, tmp_path, blm_of, lmax, mmax):
    """{detector name: path} of b_lm files for the focal plane's pairs, in TOAST's beam frames: the A
    detectors (psi_pol 0) share beam_A.fits = blm_of("A"), the B detectors (psi_pol 90 deg) beam_B.fits =
    blm_of("B"), each written once with healpy.write_alm."""
    files = {}
    for name, psi_pol in zip(fp.detector_data["name"], fp.detector_data["psi_pol"]):
        angle = float(u.Quantity(psi_pol).to_value(u.deg))
        assert angle in (0.0, 90.0)
        which = "A" if angle == 0.0 else "B"
        path = str(tmp_path / f"beam_{which}.fits")
        if not os.path.exists(path):
            hp.write_alm(path, blm_of(which), lmax=lmax, mmax_in=mmax, overwrite=True)
        files[str(name)] = path
    return files


def toast_totalconvolve(data, fp, alm, lmax, tmp_path, det_data, hwp_angle=None, beam_files=None, beammmax=2,
                        detectors=None):
    """TOAST's own beam convolution of the sky `alm` into `det_data`: with the Gaussian beam, or with the
    b_lm files `beam_files` (detector name -> path; `beammmax` at least their mmax); all detectors, or
    `detectors`."""
    sky_file = str(tmp_path / "sky_alm.fits")
    hp.write_alm(sky_file, alm, lmax=lmax, overwrite=True)
    # psi_pol: the polarization direction in the beam frame. TOAST's SimTotalconvolve reads it from the
    # column `pol_angle` (while testing for `psi_pol`): give it that column. The beam of a B detector,
    # in its beam frame, is polarized at 90 deg (TOAST's own test beams flip Q for B detectors).
    fp.detector_data["pol_angle"] = fp.detector_data["psi_pol"]
    if beam_files is None:
        beam_files = pair_beam_files(
            fp, tmp_path, lambda a: gaussian_blm(lmax, FWHM, EPSILON, sign=1.0 if a == "A" else -1.0), lmax, 2)
    op = TotalconvolveForCurrentDucc0(
        comm=None, detector_pointing=toast.ops.PointingDetectorSimple(quats="tc_quats"), sky_file=sky_file,
        beam_file_dict=beam_files, sky_file_dict={}, dxx=False, det_data=det_data, fwhm=0 * u.rad, lmax=lmax,
        beammmax=beammmax, epsilon=1e-7, hwp_angle=hwp_angle)
    op.apply(data, detectors=detectors)


def test_pixel_convolve_matches_toast_total_convolution(tmp_path):
    """Across both poles (docs/validation.md, L): the scan passes within 0.25 deg of each."""
    nside, lmax = 256, 512
    fp = focalplane()
    data = satellite_data(fp, across_poles=True)
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
    toast.ops.PointingDetectorSimple(quats="pole_quats").apply(data)
    theta = np.array([qa.to_iso_angles(ob.detdata["pole_quats"][d])[0] for d in dets])
    near = np.minimum(theta, np.pi - theta) < np.radians(10)
    print(f"PixelConvolve vs TOAST SimTotalconvolve: {len(dets)} detectors x {ours.shape[1]} samples, sky NSIDE "
          f"{nside} (lmax {lmax}), FWHM 1 deg, pol_leakage {EPSILON}: relative RMS {rms:.2e} (worst detector {worst:.2e}); "
          f"{near.sum()} samples within 10 deg of the poles, {np.count_nonzero(np.minimum(theta, np.pi - theta) < np.radians(1))} "
          f"within 1 deg: {relative_rms(ours[near], reference[near]):.2e} there")
    assert near.sum() > 1000
    assert rms <= 5e-5 and worst <= 1e-4
    # The polarization alone, held to its own RMS: the pair differences (detectors A and B of a pixel
    # are neighbours in the table).
    assert [d[-5] for d in dets[:2]] == ["A", "B"]
    pol = relative_rms(ours[0::2] - ours[1::2], reference[0::2] - reference[1::2])
    print(f"pair differences (polarization): relative RMS {pol:.2e}")
    assert pol <= 1e-3


def test_beam_files_match_toast_total_convolution(tmp_path):
    """The same b_lm files (an elliptical polarized beam with cross-polar leakage, its centre 0.3 deg off
    the axis so that odd m hold coefficients too, mmax 12; polarized at psi_pol in the beam frame: 0 for
    A detectors, 90 deg for B) through TOAST's SimTotalconvolve (calibrate=True) and PixelConvolve's
    beam_file_dict, on four of the hexagon's detectors (the pairs of the centre pixel and of an outer one)
    with pol_leakage 0.05."""
    from toast import qarray as qa

    nside, lmax = 256, 512
    lmax_beam, mmax = 768, 12
    fp = focalplane()
    data = satellite_data(fp)
    alm = smooth_sky_alm(lmax, seed=3, smoothing_fwhm=np.radians(0.5))
    sky = pisco.Sky.from_maps(hp.alm2map(alm, nside, lmax=lmax, pol=True), units="K")
    # One beam, polarized along its frame's x axis; a B detector's file holds it polarized along y
    # (E and B negated: the polarization turned by 90 deg in the same pattern).
    blm = offset_elliptical_blm(lmax_beam, mmax, FWHM, 1.5, np.radians(25.0), psi_pol=0.0,
                                cross_polar_leakage=0.02, offset=np.radians(0.3), offset_angle=np.radians(40.0))
    odd = np.concatenate([np.full(lmax_beam - m + 1, m % 2 == 1) for m in range(mmax + 1)])
    assert np.max(np.abs(blm[0, odd])) > 0.1 * np.max(np.abs(blm[0]))
    flip = np.array([1.0, -1.0, -1.0])[:, None]
    beam_files = pair_beam_files(fp, tmp_path, lambda a: blm if a == "A" else blm * flip, lmax_beam, mmax)
    assert sorted(set(beam_files.values())) == [str(tmp_path / "beam_A.fits"), str(tmp_path / "beam_B.fits")]
    ob = data.obs[0]
    dets = list(ob.local_detectors[0:2]) + list(ob.local_detectors[6:8])
    assert [d[-5] for d in dets] == ["A", "B", "A", "B"]
    toast_totalconvolve(data, fp, alm, lmax, tmp_path, "totalconvolve", beam_files=beam_files, beammmax=mmax,
                        detectors=dets)
    # Sampled at FWHM / 40 (the default step, FWHM / 16.8 for a Gaussian, is compared below), out to 3 deg
    # (5 sigma of the major axis beyond the offset).
    op = pisco.toast.PixelConvolve(sky=sky, det_data="pisco", backend="cpu", beam_file_dict=beam_files,
                                   beam_file_grid_step=FWHM / 40, beam_file_rho_max=np.radians(3.0))
    start = time.perf_counter()
    op.exec(data, detectors=dets)
    assert len(op._file_beams) == 2  # one beamsor per (file, zeta)
    op.finalize(data)
    seconds = time.perf_counter() - start
    reference = np.array([ob.detdata["totalconvolve"][d] for d in dets])
    ours = np.array([ob.detdata["pisco"][d] for d in dets])
    toast.ops.PointingDetectorSimple(quats="pole_quats").apply(data)
    theta = np.array([qa.to_iso_angles(ob.detdata["pole_quats"][d])[0] for d in dets])
    away = np.abs(np.cos(theta)) < np.cos(np.radians(10.0))
    rms = relative_rms(ours, reference)
    worst = max(relative_rms(ours[i], reference[i]) for i in range(len(dets)))
    pol = relative_rms(ours[0::2] - ours[1::2], reference[0::2] - reference[1::2])
    print(f"PixelConvolve(beam_file_dict) vs TOAST SimTotalconvolve, the same b_lm files (ellipticity 1.5, 0.3 deg "
          f"off axis, cross-polar 0.02, lmax {lmax_beam}, mmax {mmax}), grid step FWHM / 40, rho_max 3 deg: "
          f"{len(dets)} detectors x "
          f"{ours.shape[1]} samples, sky NSIDE {nside} (lmax {lmax}): relative RMS {rms:.2e} (worst detector "
          f"{worst:.2e}; pair differences {pol:.2e}); {np.count_nonzero(~away)} samples within 10 deg of the poles; "
          f"{seconds:.1f} s")
    assert_everywhere(ours, reference, away, 3e-4)
    assert pol <= 1e-3
    # The default grid step and rho_max (5 deg), one detector.
    pisco.toast.PixelConvolve(sky=sky, det_data="pisco_default", backend="cpu", beam_file_dict=beam_files).apply(
        data, detectors=dets[2:3])
    default = relative_rms(ob.detdata["pisco_default"][dets[2]], reference[2])
    print(f"  the default grid step (FWHM / 16.8) and rho_max, detector {dets[2]}: relative RMS {default:.2e} (at "
          f"FWHM / 40: {relative_rms(ours[2], reference[2]):.2e})")
    assert default <= 5e-4
    # The beam turned by 180 deg (b_lm (-1)^m: the frame SimTotalconvolve hands ducc0, psi - psi_pol + pi,
    # taken as PISCO-VK's antenna frame) misses; the dict takes precedence over the pattern.
    sign = np.concatenate([np.full(lmax_beam - m + 1, (-1.0) ** m) for m in range(mmax + 1)])
    turned = {dets[2]: str(tmp_path / "turned.fits")}
    b = np.array([hp.read_alm(beam_files[dets[2]], hdu=h) for h in (1, 2, 3)])
    hp.write_alm(turned[dets[2]], b * sign, lmax=lmax_beam, mmax_in=mmax, overwrite=True)
    pisco.toast.PixelConvolve(sky=sky, det_data="pisco_turned", backend="cpu", beam_file="/nowhere/{detector}",
                              beam_file_dict=turned).apply(data, detectors=dets[2:3])
    wrong = relative_rms(ob.detdata["pisco_turned"][dets[2]], reference[2])
    print(f"  the beam turned by 180 deg, detector {dets[2]}: relative RMS {wrong:.2e}")
    assert wrong > 0.05


def test_beam_file_errors_and_calibration(tmp_path):
    """A detector without a file or with a missing file fails, naming both; normalize_beam and
    beam_file_mmax as SimTotalconvolve's normalize_beam and beammmax; the gain is 2 Omega~ /
    (1 + pol_leakage) with epsilon 0."""
    lmax, mmax = 256, 4
    fp = focalplane(n_pix=1)
    data = satellite_data(fp, seconds=20.0)
    ob = data.obs[0]
    dets = list(ob.local_detectors)
    sky = pisco.Sky.from_maps(hp.alm2map(smooth_sky_alm(128, 1, np.radians(2)), 64, lmax=128, pol=True))
    blm = offset_elliptical_blm(lmax, mmax, np.radians(2.0), 1.3, 0.4, psi_pol=0.0)
    path = str(tmp_path / "beam.fits")
    hp.write_alm(path, blm, lmax=lmax, mmax_in=mmax, overwrite=True)
    with pytest.raises(RuntimeError, match=f"detector {dets[1]} has no beam file"):
        pisco.toast.PixelConvolve(sky=sky, backend="cpu", beam_file_dict={dets[0]: path}).apply(data)
    # A detector without a file is fine while it is not convolved.
    pisco.toast.PixelConvolve(sky=sky, backend="cpu", det_data="one", beam_file_dict={dets[0]: path}).apply(
        data, detectors=[dets[0]])
    missing = str(tmp_path / "nothing_{detector}.fits")
    with pytest.raises(RuntimeError, match=f"detector {dets[0]}: the beam file .*nothing_{dets[0]}.fits does not "
                                           "exist"):
        pisco.toast.PixelConvolve(sky=sky, backend="cpu", beam_file=missing).apply(data)
    with pytest.raises(RuntimeError, match="not both"):
        pisco.toast.PixelConvolve(sky=sky, backend="cpu", beam_file=path,
                                  beam=pisco.Beamsor.gaussian(FWHM)).apply(data)
    with pytest.raises(Exception, match="mc cannot be negative"):
        pisco.toast.PixelConvolve(sky=sky, beam_file=path, mc=-1)
    # The file pattern, as SimTotalconvolve's beam_file takes it: {detector} and {mc}.
    for d in dets:
        hp.write_alm(str(tmp_path / f"beam_{d}_7.fits"), blm, lmax=lmax, mmax_in=mmax, overwrite=True)
    pisco.toast.PixelConvolve(sky=sky, backend="cpu", det_data="pattern",
                              beam_file=str(tmp_path / "beam_{detector}_{mc}.fits"), mc=7).apply(data)
    pisco.toast.PixelConvolve(sky=sky, backend="cpu", det_data="dict",
                              beam_file_dict={d: path for d in dets}).apply(data)
    for d in dets:
        assert np.any(ob.detdata["pattern"][d] != 0)
        assert np.array_equal(ob.detdata["pattern"][d], ob.detdata["dict"][d])
    # The engine's detectors: epsilon 0, gain 2 Omega~ / (1 + pol_leakage); normalize_beam scales it by
    # 1 / (2 sqrt(pi) b_00), beam_file_mmax keeps m <= 2.
    quats = np.ascontiguousarray(ob.shared["boresight_radec"].data)
    runs = {}
    for key, traits in (("plain", {}), ("normalized", dict(normalize_beam=True)), ("m2", dict(beam_file_mmax=2))):
        op = pisco.toast.PixelConvolve(sky=sky, backend="cpu", det_data=key, beam_file=path, **traits)
        op.apply(data)
        engine, index, _ = op._engine_for(ob.telescope.focalplane, False)
        for d in dets:
            det = engine.focal_plane[index[d]]
            beam, factor = next(v for k, v in op._file_beams.items() if k[1] == det.zeta)
            assert det.epsilon == 0.0
            assert det.gain == pytest.approx(2 * beam.omega_tilde * factor / (1 + EPSILON), rel=1e-15)
        runs[key] = np.array([ob.detdata[key][d] for d in dets])
        op.finalize(data)
    b00 = blm[0, 0].real
    assert np.allclose(runs["normalized"], runs["plain"] / (2 * np.sqrt(np.pi) * b00), rtol=1e-12, atol=0)
    assert relative_rms(runs["m2"], runs["plain"]) > 1e-6
    m2 = pisco.toast.PixelConvolve(sky=sky, backend="cpu", det_data="m2_file", beam_file_dict={
        d: str(tmp_path / "beam_m2.fits") for d in dets})
    hp.write_alm(str(tmp_path / "beam_m2.fits"), np.array([hp.resize_alm(b, lmax, mmax, lmax, 2) for b in blm]),
                 lmax=lmax, mmax_in=2, overwrite=True)
    m2.apply(data)
    assert np.allclose(np.array([ob.detdata["m2_file"][d] for d in dets]), runs["m2"], rtol=1e-12,
                       atol=1e-12 * np.max(np.abs(runs["m2"])))


def toast_plate_reference(data, alm, lmax):
    """TOAST's own ideal plate, without a convolution code of its own in the way: its StokesWeights
    with hwp_angle (IQU, the focal plane's gamma) applied, sample by sample, to the sky smoothed by
    the Gaussian beam (T window on I, polarized window on Q and U, healpy's) evaluated exactly at each
    detector's line of sight by ducc0's synthesis_general. Returns (detectors, n) TOD."""
    import ducc0
    from toast import qarray as qa

    detpointing = toast.ops.PointingDetectorSimple(quats="plate_quats")
    toast.ops.StokesWeights(mode="IQU", detector_pointing=detpointing, weights="plate_weights",
                            hwp_angle="hwp_angle").apply(data)
    bl = hp.gauss_beam(FWHM, lmax=lmax, pol=True)
    smoothed = np.array([hp.almxfl(alm[k], bl[:, k]) for k in range(3)])
    ob = data.obs[0]
    tod = []
    for det in ob.local_detectors:
        theta, phi, _ = qa.to_iso_angles(ob.detdata["plate_quats"][det])
        loc = np.ascontiguousarray(np.stack([theta, np.mod(phi, 2 * np.pi)], axis=1))
        i = ducc0.sht.synthesis_general(alm=smoothed[0:1], spin=0, lmax=lmax, loc=loc, epsilon=1e-12, nthreads=2)[0]
        q, u_ = ducc0.sht.synthesis_general(alm=smoothed[1:3], spin=2, lmax=lmax, loc=loc, epsilon=1e-12, nthreads=2)
        w = ob.detdata["plate_weights"][det]
        tod.append(w[:, 0] * i + w[:, 1] * q + w[:, 2] * u_)
    return np.array(tod)


def test_pixel_convolve_through_a_plate_matches_toast(tmp_path):
    """A satellite observation with TOAST's plate turning at 20 rpm (SimSatellite's hwp_angle) and
    the hexagon's detectors turned so that gamma matters: PixelConvolve's ideal plates (gamma from the
    focal plane) against TOAST's ideal plate; and TOAST's SimTotalconvolve with hwp_angle, whose own
    plate convention is mapped onto PISCO-VK's."""
    nside, lmax = 256, 512
    fp = turned_focalplane(focalplane(), np.radians(10.0))
    data = satellite_data(fp, hwp_rpm=20.0)
    ob = data.obs[0]
    dets = list(ob.local_detectors)
    h = np.array(ob.shared["hwp_angle"].data, dtype=np.float64)
    alm = smooth_sky_alm(lmax, seed=3, smoothing_fwhm=np.radians(0.5))
    sky = pisco.Sky.from_maps(hp.alm2map(alm, nside, lmax=lmax, pol=True), units="K")
    pisco.toast.PixelConvolve(sky=sky, det_data="pisco", backend="cpu").apply(data)
    ours = np.array([ob.detdata["pisco"][d] for d in dets])
    reference = toast_plate_reference(data, alm, lmax)
    rms = relative_rms(ours, reference)
    worst = max(relative_rms(ours[i], reference[i]) for i in range(len(dets)))
    pol = relative_rms(ours[0::2] - ours[1::2], reference[0::2] - reference[1::2])
    print(f"PixelConvolve with ideal plates vs TOAST's plate (StokesWeights with hwp_angle x the beam-smoothed "
          f"sky): {len(dets)} detectors x {len(h)} samples, sky NSIDE {nside} (lmax {lmax}), FWHM 1 deg, "
          f"pol_leakage {EPSILON}, 20 rpm: relative RMS {rms:.2e} (worst detector {worst:.2e}; pair differences "
          f"{pol:.2e})")
    assert rms <= 1e-4 and worst <= 2e-4 and pol <= 1e-3
    # The comparison tells the plate's conventions apart: the angle in the other sense misses by O(1).
    ob.shared.create_column("minus_hwp", (ob.n_local_samples,))
    ob.shared["minus_hwp"].set(-h if ob.comm.group_rank == 0 else None, offset=(0,), fromrank=0)
    pisco.toast.PixelConvolve(sky=sky, det_data="pisco_minus", hwp_angle="minus_hwp", backend="cpu").apply(data)
    wrong = relative_rms(np.array([ob.detdata["pisco_minus"][d] for d in dets]), reference)
    print(f"  the plate's angle in the other sense: relative RMS {wrong:.2f}")
    assert wrong > 0.1

    # TOAST 3.0.6's SimTotalconvolve with hwp_angle adds 2 hwp_angle to the detector's polarization
    # angle psi_pol and weighs its polarized convolutions by cos and sin of 4 psi_pol: the polarization
    # is turned by 4 h, gamma unused. That is PISCO-VK's ideal plate turned to 2 h with gamma = 0 (an
    # ideal plate turns it by 2 (h - gamma)), not TOAST's own StokesWeights: compare in that convention.
    toast_totalconvolve(data, fp, alm, lmax, tmp_path, "totalconvolve", hwp_angle="hwp_angle")
    theirs = np.array([ob.detdata["totalconvolve"][d] for d in dets])
    table = fp.detector_data.copy()
    table["gamma"] = np.zeros(len(table)) * u.rad
    plates = pisco.FocalPlane.from_toast(table, hwp=pisco.HalfWavePlate())
    assert all(d.hwp.gamma == 0.0 for d in plates.detectors)
    quats = np.ascontiguousarray(ob.shared["boresight_radec"].data, dtype=np.float64)
    with pisco.Engine(sky, pisco.Beamsor.gaussian(FWHM, rho_max=2.5 * FWHM), plates, backend="cpu") as engine:
        mapped = np.array([engine.convolve(d, boresight_quats=quats, hwp_angle=2 * h) for d in dets])
    tc_rms = relative_rms(mapped, theirs)
    tc_toast = relative_rms(theirs, reference)
    print(f"TOAST SimTotalconvolve with hwp_angle vs PISCO-VK's ideal plate at 2 h, gamma 0: relative RMS "
          f"{tc_rms:.2e}; SimTotalconvolve vs TOAST's own StokesWeights plate: {tc_toast:.2f}")
    assert tc_rms <= 1e-4


def test_plate_beams_of_an_ideal_plate_are_the_plate_model(tmp_path):
    """PixelConvolve's plate_beams (docs/changing.md): each detector's beam given as five beams with an
    ideal plate in them (a 1 deg Gaussian times the plate's Mueller matrix at plate angles k pi / 5 from
    the detector's axis) on a satellite observation with TOAST's plate turning at 20 rpm and detectors
    turned so that gamma matters, against the same Gaussian behind PixelConvolve's ideal plate model
    (itself checked against TOAST's plate above): the same TOD to rounding."""
    nside = 128
    fp = turned_focalplane(focalplane(), np.radians(10.0))
    data = satellite_data(fp, seconds=300.0, hwp_rpm=20.0)
    ob = data.obs[0]
    dets = list(ob.local_detectors)
    sky = pisco.Sky.from_maps(hp.alm2map(smooth_sky_alm(2 * nside, seed=5, smoothing_fwhm=np.radians(0.5)), nside,
                                         lmax=2 * nside, pol=True), units="K")
    s = FWHM / np.sqrt(8 * np.log(2.0))
    rho, step = 2.5 * FWHM, FWHM / 16

    def gauss(r, sigma):
        g = np.exp(-r * r / (2 * s * s))
        return np.diag([g, g, g, g])

    plain = pisco.Beamsor.from_field(gauss, rho, step, "gaussian")
    turning = []
    for k in range(5):
        m = np.array(pisco.rotated_mueller(pisco.ideal_hwp_mueller(), np.pi * k / 5))
        turning.append(pisco.Beamsor.from_field(lambda r, sigma, m=m: gauss(r, sigma) @ m, rho, step, f"plate {k}"))
    pisco.toast.PixelConvolve(sky=sky, det_data="modelled", beams={d: plain for d in dets}, backend="cpu",
                              zero=True).apply(data)
    pisco.toast.PixelConvolve(sky=sky, det_data="turning", beams={d: plain for d in dets},
                              plate_beams={d: turning for d in dets}, backend="cpu", zero=True).apply(data)
    modelled = np.array([ob.detdata["modelled"][d] for d in dets])
    ours = np.array([ob.detdata["turning"][d] for d in dets])
    rms = relative_rms(ours, modelled)
    print(f"PixelConvolve plate_beams (an ideal plate as five beams) vs its plate model: relative RMS {rms:.2e}")
    assert rms <= 1e-12
    assert relative_rms(modelled[0::2] - modelled[1::2], modelled[0::2]) > 1e-3  # the plate modulates the pairs
    with pytest.raises(traitlets.TraitError, match="expected two or more pisco.Beamsor"):
        pisco.toast.PixelConvolve(plate_beams={dets[0]: [plain]})
    with pytest.raises(RuntimeError, match="plate_beams names detectors the focal plane does not hold"):
        pisco.toast.PixelConvolve(sky=sky, det_data="x", plate_beams={"nobody": turning}, backend="cpu").apply(data)


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


def test_plate_options_and_missing_inputs():
    fp = turned_focalplane(focalplane(n_pix=1), np.radians(10.0))
    data = satellite_data(fp, seconds=30.0, hwp_rpm=30.0)
    sky = pisco.Sky.from_maps(hp.alm2map(smooth_sky_alm(128, 1, np.radians(2)), 64, lmax=128, pol=True))
    beam = pisco.Beamsor.gaussian(FWHM, rho_max=2.5 * FWHM)
    ob = data.obs[0]
    h = np.array(ob.shared["hwp_angle"].data)
    gamma = {str(n): float(u.Quantity(g).to_value(u.rad)) for n, g in zip(fp.detector_data["name"],
                                                                          fp.detector_data["gamma"])}

    def run(key, **traits):
        pisco.toast.PixelConvolve(sky=sky, beam=beam, det_data=key, backend="cpu", **traits).apply(data)
        return {d: ob.detdata[key][d].copy() for d in ob.local_detectors}

    ideal = run("ideal")
    plain = run("plain", hwp_angle=None)  # no plate: hwp_angle=None ignores the observation's
    as_list = run("as_list", hwp_mueller=[1, 0, 0, 0, 0, 1, 0, 0, 0, 0, -1, 0, 0, 0, 0, -1])
    leaky = np.diag([0.98, 0.98, -0.97, -0.95]) + 0.01  # a passive plate: M00 + |(M01, M02, M03)| < 1
    aperture = run("aperture", hwp_mueller=leaky)
    detector = run("detector", hwp_mueller=leaky, hwp_placement="detector")
    # The plates' gamma and angles reach the engine: the engine's own ideal plate gives the same TOD.
    table_fp = pisco.FocalPlane.from_toast(fp, hwp=pisco.HalfWavePlate())
    quats = np.ascontiguousarray(ob.shared["boresight_radec"].data)
    with pisco.Engine(sky, beam, table_fp, backend="cpu") as engine:
        for det in ob.local_detectors:
            assert table_fp[det].hwp.gamma == pytest.approx(gamma[det], abs=1e-15)
            assert np.allclose(ideal[det], engine.convolve(det, boresight_quats=quats, hwp_angle=h), rtol=0,
                               atol=1e-12 * np.max(np.abs(ideal[det])))
            assert relative_rms(ideal[det], plain[det]) > 0.1  # the plate modulates
            assert np.array_equal(as_list[det], ideal[det])
            assert relative_rms(aperture[det], ideal[det]) > 1e-3
            # A round co-polar beam commutes with the plate: both placements give the same TOD.
            assert relative_rms(detector[det], aperture[det]) < 1e-12
    # The plate's traits go through TOAST's config system (the matrix kept as its 16 numbers).
    op = pisco.toast.PixelConvolve(name="pc", sky=sky, beam=beam, hwp_mueller=leaky, hwp_placement="detector")
    assert op.hwp_mueller == [float(x) for x in leaky.ravel()]
    assert op.get_config()["operators"]["pc"]["hwp_placement"]["value"] == "detector"
    with pytest.raises(Exception, match="hwp_mueller: expected 16 numbers"):
        pisco.toast.PixelConvolve(sky=sky, beam=beam, hwp_mueller=[1.0] * 15)
    with pytest.raises(Exception, match="hwp_mueller: the Mueller matrix must be finite"):
        pisco.toast.PixelConvolve(sky=sky, beam=beam, hwp_mueller=[[np.nan] * 4] * 4)
    # A passive element's bounds (docs/physics.md, "Physical bounds on Mueller matrices").
    with pytest.raises(Exception, match=r"hwp_mueller: transmits up to 1.05 times the light \(M00 \+"):
        pisco.toast.PixelConvolve(sky=sky, beam=beam, hwp_mueller=np.diag([1.05, 1.0, -1.0, -1.0]))
    with pytest.raises(Exception, match="hwp_placement must be 'aperture' or 'detector'"):
        pisco.toast.PixelConvolve(sky=sky, beam=beam, hwp_placement="sky")
    ob.shared.create_column("bad_hwp", (ob.n_local_samples,))
    bad = h.copy()
    bad[5] = np.nan
    ob.shared["bad_hwp"].set(bad if ob.comm.group_rank == 0 else None, offset=(0,), fromrank=0)
    with pytest.raises(ValueError, match="'bad_hwp' is not finite"):
        pisco.toast.PixelConvolve(sky=sky, beam=beam, hwp_angle="bad_hwp", backend="cpu").apply(data)
    with pytest.raises(RuntimeError, match="give sky"):
        pisco.toast.PixelConvolve(beam=beam, hwp_angle=None).apply(data)
    with pytest.raises(RuntimeError, match="no shared 'nothing'"):
        pisco.toast.PixelConvolve(sky=sky, beam=beam, hwp_angle=None, boresight="nothing").apply(data)
    with pytest.raises(Exception, match="beams"):
        pisco.toast.PixelConvolve(sky=sky, beams={"x": "not a beam"})


def test_sources_match_toast_sim_catalog(tmp_path):
    """PixelConvolve's sources (docs/sources.md) against TOAST's own point-source simulation, SimCatalog:
    a 10 Jy source of flat spectrum where a satellite observation's boresight crosses the celestial
    equator, seen by every detector of a 1 deg FWHM focal plane. SimCatalog samples a Gaussian beam map
    in a flat-sky approximation (offsets dphi sin(theta), dtheta) and converts Jy to K_CMB with the
    detectors' bandpass; the same flux, F = S / kcmb2jysr sr, as a pisco.SourceTrack agrees to that
    approximation's accuracy near the equator, and exactly as the beam at the source's offset
    elsewhere (tests/test_sources.cpp)."""
    fp = focalplane()
    data = satellite_data(fp, seconds=600.0)
    ob = data.obs[0]
    dets = list(ob.local_detectors)
    theta, phi, _ = qa.to_iso_angles(np.asarray(ob.shared["boresight_radec"].data))
    i = int(np.argmin(np.abs(theta - np.pi / 2)))
    catalog = tmp_path / "catalog.toml"
    catalog.write_text(f"[equatorial]\nra_deg = {float(np.degrees(phi[i]))!r}\ndec_deg = {float(90 - np.degrees(theta[i]))!r}\n"
                       "freqs_ghz = [10.0, 1000.0]\nflux_density_Jy = [10.0, 10.0]\n")
    pointing = toast.ops.PointingDetectorSimple(boresight="boresight_radec", quats="quats_radec")
    toast.ops.SimCatalog(catalog_file=str(catalog), det_data="toast_sources", detector_pointing=pointing,
                         hwp_angle="none").apply(data)
    bandpass = ob.telescope.focalplane.bandpass
    flux = {d: bandpass.convolve(d, np.array([10.0, 1000.0]) * u.GHz, np.array([10.0, 10.0])) / bandpass.kcmb2jysr(d)
            for d in dets}
    assert len(set(flux.values())) == 1  # one band for every detector
    source = pisco.SourceTrack.fixed("equatorial", theta[i], phi[i], float(flux[dets[0]]))
    pisco.toast.PixelConvolve(sky=pisco.Sky(128, units="K"), det_data="ours", sources=[source], backend="cpu",
                              zero=True).apply(data)
    theirs = np.array([ob.detdata["toast_sources"][d] for d in dets])
    ours = np.array([ob.detdata["ours"][d] for d in dets])
    seen = theirs > 1e-3 * theirs.max()
    assert seen.any(axis=1).sum() >= 6  # three pixels of the hexagon cross the source
    rms = np.sqrt(np.mean((ours - theirs)[seen] ** 2) / np.mean(theirs[seen] ** 2))
    peak = np.abs(ours - theirs).max() / theirs.max()
    print(f"PixelConvolve sources vs TOAST SimCatalog: relative RMS {rms:.2e}, worst {peak:.2e} of the peak")
    assert rms < 1e-4 and peak < 1e-4
    # Sources need the observation's times.
    with pytest.raises(traitlets.TraitError, match=r"sources\[0\] is not a pisco.SourceTrack"):
        pisco.toast.PixelConvolve(sources=["jupiter"])
    with pytest.raises(RuntimeError, match="has no shared 'no_times', which sources need"):
        pisco.toast.PixelConvolve(sky=pisco.Sky(128, units="K"), det_data="x", sources=[source], times="no_times",
                                  backend="cpu").apply(data)


def test_the_ground_through_boresight_azel_is_the_horizon_frame():
    """The ground in TOAST (docs/ground.md): PixelConvolve over a ground map (pisco.ground_sky: the horizon
    frame, longitude -azimuth) with boresight="boresight_azel", against the engine at
    pisco.horizon_pointing of the observation's own azimuth and elevation, for detectors at the
    boresight with a 1 deg beam and a uniform far-sidelobe ring at 40 deg (a response that does not
    depend on the boresight's turn): the same TOD, so TOAST's Az/El quaternions' frame is the ground
    map's. The scan at 50 deg elevation sees the ground through the ring only, and its azimuth
    sweep carries the ring across a horizon that rises to 12 deg in the east."""
    fp = focalplane(n_pix=1)
    data = ground_data(fp, seconds=300.0)
    ob = data.obs[0]
    dets = list(ob.local_detectors)
    ground = pisco.ground_sky(64, 300.0, horizon=np.radians([2.0, 12.0, 4.0, 1.0]), width=np.radians(2.0), units="K")
    beam = pisco.Beamsor.gaussian(FWHM, rho_max=np.radians(60.0), sidelobes=np.radians(8.0),
                                  far_sidelobe=(-40.0, np.radians(40.0), np.radians(6.0)))
    pisco.toast.PixelConvolve(sky=ground, beam=beam, boresight="boresight_azel", det_data="ground", backend="cpu",
                              zero=True).apply(data)
    az = np.asarray(ob.shared["azimuth"].data, dtype=np.float64)
    el = np.asarray(ob.shared["elevation"].data, dtype=np.float64)
    theta, phi, psi = pisco.horizon_pointing(az, el)
    table = pisco.focal_plane_from_toast(ob.telescope.focalplane, beam=0)
    with pisco.Engine(ground, beam, table, backend="cpu") as engine:
        for d in dets:
            offset = np.asarray(table[table.names.index(d)].offset)
            assert np.allclose(np.abs(offset), [0, 0, 0, 1], atol=1e-12)  # at the boresight
            direct = engine.convolve(d, theta, phi, psi)
            ours = np.asarray(ob.detdata["ground"][d])
            scale = np.abs(direct).max()
            assert scale > 1e-3 and np.ptp(direct) > 1e-3 * scale  # the ring sees the ground, more in the east
            assert np.abs(ours - direct).max() <= 1e-9 * scale, d
    print(f"ground through boresight_azel: {ours.min():.4g} to {ours.max():.4g} K, as at horizon_pointing")
