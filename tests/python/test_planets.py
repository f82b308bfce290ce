"""The planets' tracks (pisco.planets, docs/sources.md "Planets") against astropy's own frames: in the
ces scan's frame against astropy's topocentric CIRS (the frame the Earth rotation angle turns into the
site's horizon), in the equatorial, ecliptic and galactic frames against astropy's ICRS, Galactic and
mean-ecliptic frames of the same astrometric vector; the observers (a site's parallax on the Moon,
L2's on Jupiter); the flux of a disc; track files from Python; and the errors."""

import math

import numpy as np
import pytest

import pisco

astropy = pytest.importorskip("astropy")
from astropy import units as u  # noqa: E402
from astropy.coordinates import CIRS, EarthLocation, Galactic, BarycentricMeanEcliptic, SkyCoord  # noqa: E402
from astropy.coordinates import get_body, solar_system_ephemeris  # noqa: E402
from astropy.time import Time  # noqa: E402

from pisco import planets  # noqa: E402

START = "2026-11-28T06:00:00"
SITE = (-22.96, -67.79, 5200.0)
ARCSEC = math.pi / 180 / 3600


def offline():
    """astropy with its bundled tables only, as pisco.planets runs it."""
    return planets._offline()


def separation(theta1, phi1, theta2, phi2):
    a = np.stack([np.sin(theta1) * np.cos(phi1), np.sin(theta1) * np.sin(phi1), np.cos(theta1)], -1)
    b = np.stack([np.sin(theta2) * np.cos(phi2), np.sin(theta2) * np.sin(phi2), np.cos(theta2)], -1)
    return np.arctan2(np.linalg.norm(np.cross(a, b), axis=-1), np.sum(a * b, -1))


def test_in_the_ces_frame_a_track_is_astropys_topocentric_cirs():
    """The ces frame is the CIRS of the site, less polar motion (below an arcsecond), with UT1 = UTC."""
    times = np.arange(0.0, 4 * 3600.0 + 1, 900.0)
    for body in ("jupiter", "moon", "mars", "saturn"):
        track = planets.planet_track(body, START, times, site=SITE, flux=1.0)
        when = Time(START, scale="utc") + times * u.s
        when.delta_ut1_utc = np.zeros(times.size)
        location = EarthLocation.from_geodetic(SITE[1] * u.deg, SITE[0] * u.deg, SITE[2] * u.m)
        with offline(), solar_system_ephemeris.set("builtin"):
            cirs = get_body(body, when, location).transform_to(CIRS(obstime=when, location=location))
        off = separation(np.array(track.theta), np.array(track.phi), math.pi / 2 - cirs.dec.rad, cirs.ra.rad)
        assert off.max() < 1.0 * ARCSEC, (body, off.max() / ARCSEC)
        assert track.time == list(times)
    unix = planets.planet_track("jupiter", START, times, site=SITE, flux=1.0, unix_times=True)
    assert np.allclose(np.array(unix.time) - Time(START, scale="utc").unix, times, rtol=0, atol=1e-6)
    assert unix.theta == planets.planet_track("jupiter", START, times, site=SITE, flux=1.0).theta


def test_celestial_frames_agree_with_astropys():
    times = np.array([0.0, 86400.0, 30 * 86400.0])
    eq = planets.planet_track("jupiter", START, times, frame="equatorial", flux=1.0)
    when = Time(START, scale="utc") + times * u.s
    icrs = SkyCoord(ra=np.array(eq.phi) * u.rad, dec=(math.pi / 2 - np.array(eq.theta)) * u.rad, frame="icrs")
    for frame, other in (
        ("galactic", icrs.transform_to(Galactic())),
        ("ecliptic", icrs.transform_to(BarycentricMeanEcliptic(equinox="J2000"))),
    ):
        track = planets.planet_track("jupiter", START, times, frame=frame, flux=1.0)
        sph = other.spherical
        off = separation(np.array(track.theta), np.array(track.phi), math.pi / 2 - sph.lat.rad, sph.lon.rad)
        # IAU 1958 constants against astropy's FK4-derived galactic frame; the IAU 1976 obliquity and no
        # frame bias against astropy's IAU 2006 mean ecliptic of J2000: both well below an arcsecond.
        assert off.max() < 0.5 * ARCSEC, (frame, off.max() / ARCSEC)


def test_the_observer_moves_the_track_by_its_parallax():
    times = np.array([0.0, 3600.0])
    geo = planets.planet_track("moon", START, times, frame="equatorial", flux=1.0)
    topo = planets.planet_track("moon", START, times, frame="equatorial", site=SITE, flux=1.0)
    moon = separation(np.array(geo.theta), np.array(geo.phi), np.array(topo.theta), np.array(topo.phi))
    # The Moon's horizontal parallax is 0.9 to 1.0 deg; seen off the zenith, up to that.
    assert 0.05 * math.pi / 180 < moon.max() < 1.03 * math.pi / 180
    geo = planets.planet_track("jupiter", START, times, frame="equatorial", flux=1.0)
    l2 = planets.planet_track("jupiter", START, times, frame="equatorial", orbit="l2", flux=1.0)
    shift = separation(np.array(geo.theta), np.array(geo.phi), np.array(l2.theta), np.array(l2.phi))
    assert shift.max() < 1.5e6 / 5.8e8 and shift.max() > 1e-4  # at most 1.5e6 km over Jupiter's least distance


def test_the_flux_is_the_disc_at_its_brightness():
    # dT_RJ / dT_CMB: the Planck law's derivative at T_CMB over its Rayleigh-Jeans limit 2 k nu^2 / c^2,
    # by finite differences.
    h, k, c, t_cmb = 6.62607015e-34, 1.380649e-23, 299792458.0, 2.72548
    for ghz in (30.0, 100.0, 150.0, 353.0):
        nu = ghz * 1e9
        planck = lambda t: 2 * h * nu**3 / c**2 / math.expm1(h * nu / (k * t))  # noqa: E731
        slope = (planck(t_cmb * (1 + 1e-6)) - planck(t_cmb * (1 - 1e-6))) / (2e-6 * t_cmb)
        assert planets.rayleigh_jeans_to_cmb(ghz) == pytest.approx(2 * k * nu**2 / c**2 / slope, rel=1e-7)
    times = np.array([0.0, 86400.0 * 90])
    track = planets.planet_track("jupiter", START, times, site=SITE, brightness_temperature=170.0, frequency=150.0)
    rj = planets.planet_track("jupiter", START, times, site=SITE, brightness_temperature=170.0, units="K_RJ")
    when = Time(START, scale="utc") + times * u.s
    with offline(), solar_system_ephemeris.set("builtin"):
        d = get_body("jupiter", when, EarthLocation.from_geodetic(SITE[1] * u.deg, SITE[0] * u.deg)).distance.to_value(u.km)
    omega = math.pi * 71492.0 * 66854.0 / d**2
    assert np.allclose(rj.I, 170.0 * omega, rtol=1e-6)
    assert np.allclose(track.I, 170.0 * omega * planets.rayleigh_jeans_to_cmb(150.0), rtol=1e-6)
    micro = planets.planet_track("jupiter", START, times, site=SITE, brightness_temperature=170.0, frequency=150.0,
                                 units="uK_CMB")
    assert np.allclose(micro.I, 1e6 * np.array(track.I), rtol=1e-12)
    assert 15 / 206265 < math.sqrt(omega[0] / math.pi) < 25 / 206265  # Jupiter's radius: 15 to 25 arcsec
    assert track.Q == [0.0, 0.0]
    polarized = planets.planet_track("mars", START, [0.0], site=SITE, flux=2.0, polarization=(0.1, -0.2, 0.0))
    assert polarized.I == [2.0] and polarized.Q == [pytest.approx(0.2)] and polarized.U == [pytest.approx(-0.4)]


def test_a_track_file_written_from_python_reads_back(tmp_path):
    track = planets.planet_track("jupiter", START, np.arange(0.0, 601.0, 60.0), site=SITE, flux=3e-6)
    track.write_csv(tmp_path / "jupiter.csv")
    back = pisco.SourceTrack.read_csv(tmp_path / "jupiter.csv", "jupiter")
    assert back.name == "jupiter" and back.time == track.time and back.I == track.I
    assert np.allclose(back.theta, track.theta, rtol=0, atol=1e-15)
    assert np.allclose(back.phi, track.phi, rtol=0, atol=1e-15)
    (tmp_path / "bad.csv").write_text("time_s,theta_deg,phi_deg,I\n0,10,20,1\n1,10,20\n")
    with pytest.raises(pisco.Error, match=r"bad.csv:3: expected 4 fields, got 3"):
        pisco.SourceTrack.read_csv(tmp_path / "bad.csv", "x")
    with pytest.raises(pisco.Error, match="no such file"):
        pisco.SourceTrack.read_csv(tmp_path / "absent.csv", "x")


@pytest.mark.parametrize(
    "kwargs, message",
    [
        (dict(body="pluto"), "body: unknown body 'pluto'"),
        (dict(times=[0.0, 0.0]), "times: time 1"),
        (dict(times=[]), "times: expected a one-dimensional array"),
        (dict(times=[0.0, float("nan")]), "times: every time must be finite"),
        (dict(frame="horizon"), "frame: 'horizon'"),
        (dict(site=None), "frame 'ces' needs a site"),
        (dict(site=(95.0, 0.0)), "site: "),
        (dict(orbit="l1", frame="ecliptic", site=None), "orbit: 'l1'"),
        (dict(orbit="l2", frame="ecliptic"), "site and orbit"),
        (dict(flux=None), "give the flux either"),
        (dict(flux=None, brightness_temperature=170.0), "frequency: needed"),
        (dict(flux=None, brightness_temperature=-1.0, frequency=90.0), "brightness_temperature: -1.0"),
        (dict(units="MJy"), "units: 'MJy'"),
        (dict(start="yesterday-ish"), "start: 'yesterday-ish'"),
        (dict(polarization=(0.1, 0.2)), "polarization: "),
    ],
)
def test_bad_arguments_are_refused_by_name(kwargs, message):
    args = dict(body="jupiter", start=START, times=[0.0, 60.0], site=SITE, flux=1.0)
    args.update(kwargs)
    with pytest.raises(ValueError, match=message):
        planets.planet_track(args.pop("body"), args.pop("start"), args.pop("times"), **args)
