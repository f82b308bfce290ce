"""The tracks of the planets, the Moon and the Sun as point sources (docs/sources.md, "Planets").

:func:`planet_track` computes a body's direction and flux at a sequence of times with astropy's
ephemeris, seen from a ground site or from a spacecraft, and returns a :class:`pisco.SourceTrack`
for :meth:`pisco.Engine.add_sources`, the TOAST and litebird_sim adapters, or, written with
``SourceTrack.write_csv``, for a simulation file's ``[[sources]] file``. astropy is imported
when this module is; ``pip install astropy`` provides it.

Frames (``frame``):

- ``"ces"``: the frame of pisco-vk's constant-elevation scans (docs/config.md, ``[scan] type =
  "ces"``): the body's apparent azimuth and elevation at the site (astropy's ``AltAz``: precession,
  nutation, aberration and light time; no refraction; UT1 taken equal to UTC, as the scan takes it),
  carried to equatorial coordinates of date through the Earth rotation angle exactly as the scan
  carries its boresight. A scan pointed at the body's azimuth and elevation points at the track.
- ``"equatorial"`` (ICRS axes), ``"ecliptic"`` and ``"galactic"`` (the satellite scan's frames, with
  its constants): the astrometric direction from the observer, the body's barycentric position at
  the time its light left it minus the observer's, which is where a map in that frame has the body
  among its pixels (aberration moves both alike). The observer is the site, or with ``orbit="l2"``
  a spacecraft at the Sun-Earth L2 point (1.5e6 km from the Earth, away from the Sun), or the
  Earth's centre when neither is given.

Flux: the body as a uniform disc of brightness temperature ``brightness_temperature`` (Rayleigh-Jeans,
kelvin) over its apparent solid angle pi a b / d^2 (a, b: its equatorial and polar radii, d: its
distance at each time), converted to the sky's ``units`` at ``frequency`` (GHz): ``"K_CMB"``
(default), ``"uK_CMB"`` (the unit of pisco-vk's synthesized skies), ``"K_RJ"`` or ``"uK_RJ"``. The flux is in units times steradians, as a SourceTrack holds it. Or give
``flux`` (a number, or one per time) in those units directly. A body's rings and phase are not
modelled; the brightness temperature is the caller's (measured values depend on frequency and time).
"""

from __future__ import annotations

import contextlib
import math
import warnings
from collections.abc import Sequence

import numpy as np

from ._pisco import SourceTrack, rayleigh_jeans_in

try:
    import astropy.units as _u
    from astropy.coordinates import AltAz, EarthLocation, get_body, get_body_barycentric, solar_system_ephemeris
    from astropy.time import Time
    from astropy.utils import iers as _iers
except ImportError as e:  # pragma: no cover - the message is the point
    raise ImportError("pisco.planets needs astropy: pip install astropy") from e

__all__ = ["BODIES", "horizontal_to_ces", "planet_track", "rayleigh_jeans_to_cmb"]

# Equatorial and polar radii (km): IAU WG on Cartographic Coordinates and Rotational Elements 2015
# (Archinal et al. 2018, Celest. Mech. Dyn. Astron. 130, 22), the Moon's and the Sun's mean radii.
BODIES = {
    "sun": (695700.0, 695700.0),
    "moon": (1737.4, 1737.4),
    "mercury": (2440.53, 2438.26),
    "venus": (6051.8, 6051.8),
    "mars": (3396.19, 3376.20),
    "jupiter": (71492.0, 66854.0),
    "saturn": (60268.0, 54364.0),
    "uranus": (25559.0, 24973.0),
    "neptune": (24764.0, 24341.0),
}

# The satellite scan's frames (src/scans/satellite.cpp; docs/config.md): the IAU 1976 obliquity at
# J2000 and the IAU 1958 galactic system in J2000 coordinates.
_OBLIQUITY = math.radians(23.4392911)
_NGP_RA, _NGP_DEC, _NCP_L = math.radians(192.85948), math.radians(27.12825), math.radians(122.93192)
_L2_DISTANCE_KM = 1.5e6


def rayleigh_jeans_to_cmb(frequency: float) -> float:
    """The factor that turns a Rayleigh-Jeans temperature into a CMB thermodynamic one at `frequency`
    (GHz): (e^x - 1)^2 / (x^2 e^x), x = h nu / k T_CMB (pisco.rayleigh_jeans_in's)."""
    if not (frequency > 0 and math.isfinite(frequency)):
        raise ValueError(f"frequency must be a positive number of GHz, got {frequency!r}")
    return rayleigh_jeans_in("K_CMB", 1.0, frequency)


def _rotation_z(a: float) -> np.ndarray:
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def _rotation_y(a: float) -> np.ndarray:
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def _rotation_x(a: float) -> np.ndarray:
    c, s = math.cos(a), math.sin(a)
    return np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])


def _from_equatorial(frame: str) -> np.ndarray:
    """The matrix that takes an equatorial (ICRS-axis) vector to `frame`'s axes."""
    if frame == "equatorial":
        return np.eye(3)
    if frame == "ecliptic":
        return _rotation_x(_OBLIQUITY).T
    # The galactic basis in equatorial axes: R_z(ra_ngp) R_y(pi/2 - dec_ngp) R_z(pi - l_ncp).
    basis = _rotation_z(_NGP_RA) @ _rotation_y(math.pi / 2 - _NGP_DEC) @ _rotation_z(math.pi - _NCP_L)
    return basis.T


def _earth_rotation_angle(unix: np.ndarray) -> np.ndarray:
    """The Earth rotation angle (IERS 2003) from Unix times, UT1 = UTC, as the ces scan computes it."""
    days = unix / 86400.0 - 10957.5
    whole = np.floor(days)
    turns = 0.7790572732640 + 0.00273781191135448 * days + (days - whole)
    return 2 * math.pi * (turns - np.floor(turns))


def horizontal_to_ces(az: np.ndarray, el: np.ndarray, unix: np.ndarray, latitude: float, longitude: float):
    """(theta, phi) in the ces scan's frame of a direction at azimuth `az` (from north towards east)
    and elevation `el` (radians) seen at Unix time `unix` from latitude and east longitude (radians)."""
    lst = _earth_rotation_angle(np.asarray(unix, dtype=float)) + longitude
    sl, cl = math.sin(latitude), math.cos(latitude)
    se, ce, sa, ca = np.sin(el), np.cos(el), np.sin(az), np.cos(az)
    sin_dec = sl * se + cl * ce * ca
    cdch = cl * se - sl * ce * ca
    cdsh = -ce * sa
    theta = np.arctan2(np.hypot(cdch, cdsh), sin_dec)
    phi = np.mod(lst - np.arctan2(cdsh, cdch), 2 * math.pi)
    return theta, phi


@contextlib.contextmanager
def _offline():
    """astropy without downloads: its bundled IERS and leap-second tables (UT1 is taken as UTC and
    polar motion is below an arcsecond, so nothing here needs the latest ones)."""
    with _iers.conf.set_temp("auto_download", False), _iers.conf.set_temp("auto_max_age", None):
        with warnings.catch_warnings():
            warnings.filterwarnings("ignore", module=r"astropy\.")
            warnings.filterwarnings("ignore", message=r".*(IERS|leap.second|dubious year).*")
            yield


def _start_time(start) -> Time:
    if isinstance(start, Time):
        return Time(start, scale="utc")
    if isinstance(start, (int, float, np.floating, np.integer)):
        if not math.isfinite(float(start)):
            raise ValueError(f"start must be a finite Unix time, got {start!r}")
        return Time(float(start), format="unix", scale="utc")
    try:
        return Time(start, scale="utc")
    except Exception as e:
        raise ValueError(f"start: {start!r} is not a time astropy reads (e.g. '2026-11-28T06:00:00')") from e


def planet_track(
    body: str,
    start,
    times: Sequence[float] | np.ndarray,
    *,
    site: tuple[float, float] | tuple[float, float, float] | None = None,
    orbit: str | None = None,
    frame: str = "ces",
    brightness_temperature: float | None = None,
    frequency: float | None = None,
    units: str = "K_CMB",
    flux: float | Sequence[float] | np.ndarray | None = None,
    polarization: tuple[float, float, float] = (0.0, 0.0, 0.0),
    name: str | None = None,
    unix_times: bool = False,
) -> SourceTrack:
    """The track of `body` (a key of :data:`BODIES`) at `times` (seconds from `start`, strictly
    increasing; sample i of a run at i / its rate), as a SourceTrack whose times are `times`, or with
    `unix_times` the Unix times of those instants (the clock of TOAST's and litebird_sim's samples).

    start: the UTC time of `times`' zero: an ISO string ("2026-11-28T06:00:00"), an astropy Time or a
    Unix time (seconds). site: (latitude, east longitude) in degrees, and optionally the height in
    metres (default 0), as the ces scan's latitude_deg and longitude_deg. orbit: "l2" for a spacecraft
    at L2 (frames equatorial, ecliptic, galactic). frame: "ces" (needs a site), "equatorial",
    "ecliptic" or "galactic". Flux: `brightness_temperature` (K, Rayleigh-Jeans) with `frequency`
    (GHz; needed for units "K_CMB"), or `flux` in the units times steradians; `polarization` the
    fractions (Q/I, U/I, V/I) of the flux (COSMO, in the track's frame). Errors are ValueError naming
    the argument."""
    key = str(body).lower()
    if key not in BODIES:
        raise ValueError(f"body: unknown body {body!r}; expected one of {', '.join(BODIES)}")
    t = np.asarray(times, dtype=float)
    if t.ndim != 1 or t.size == 0:
        raise ValueError("times: expected a one-dimensional array of seconds from start, with at least one time")
    if not np.all(np.isfinite(t)):
        raise ValueError("times: every time must be finite")
    if t.size > 1 and not np.all(np.diff(t) > 0):
        k = int(np.argmin(np.diff(t) > 0)) + 1
        raise ValueError(f"times: time {k} ({t[k]!r}) does not follow {t[k - 1]!r}; times must increase strictly")
    if frame not in ("ces", "equatorial", "ecliptic", "galactic"):
        raise ValueError(f"frame: {frame!r}; expected 'ces', 'equatorial', 'ecliptic' or 'galactic'")
    if orbit not in (None, "l2"):
        raise ValueError(f"orbit: {orbit!r}; expected 'l2' or None")
    if orbit is not None and site is not None:
        raise ValueError("site and orbit: give one observer, a ground site or a spacecraft's orbit")
    if frame == "ces" and site is None:
        raise ValueError("frame 'ces' needs a site (latitude_deg, longitude_deg[, height_m])")
    location = None
    if site is not None:
        s = tuple(float(x) for x in site)
        if len(s) not in (2, 3) or not all(math.isfinite(x) for x in s) or abs(s[0]) > 90:
            raise ValueError(f"site: {site!r}; expected (latitude_deg in [-90, 90], longitude_deg[, height_m])")
        latitude, longitude = math.radians(s[0]), math.radians(s[1])
        location = EarthLocation.from_geodetic(s[1] * _u.deg, s[0] * _u.deg, (s[2] if len(s) == 3 else 0.0) * _u.m)
    if units not in ("K_CMB", "uK_CMB", "K_RJ", "uK_RJ"):
        raise ValueError(f"units: {units!r}; expected 'K_CMB', 'uK_CMB', 'K_RJ' or 'uK_RJ'")
    if (flux is None) == (brightness_temperature is None):
        raise ValueError("give the flux either as brightness_temperature (with frequency) or as flux, not both")
    if brightness_temperature is not None and not (
        math.isfinite(brightness_temperature) and brightness_temperature >= 0
    ):
        raise ValueError(f"brightness_temperature: {brightness_temperature!r}; expected kelvin, not negative")
    if brightness_temperature is not None and units.endswith("CMB") and frequency is None:
        raise ValueError("frequency: needed (GHz) to give a brightness temperature in K_CMB")
    fractions = tuple(float(x) for x in polarization)
    if len(fractions) != 3 or not all(math.isfinite(x) for x in fractions):
        raise ValueError(f"polarization: {polarization!r}; expected three finite fractions (Q/I, U/I, V/I)")

    epoch = _start_time(start)
    when = epoch + t * _u.s
    with _offline(), solar_system_ephemeris.set("builtin"):
        if frame == "ces":
            when.delta_ut1_utc = np.zeros(t.size)  # UT1 = UTC, as the scan's Earth rotation angle
            apparent = get_body(key, when, location)
            horizontal = apparent.transform_to(AltAz(obstime=when, location=location, pressure=0 * _u.hPa))
            theta, phi = horizontal_to_ces(
                horizontal.az.rad, horizontal.alt.rad, when.unix, latitude, longitude
            )
            distance = apparent.distance.to_value(_u.km)
        else:
            observer = get_body_barycentric("earth", when).xyz.to_value(_u.km).T
            if location is not None:
                observer = observer + location.get_gcrs_posvel(when)[0].xyz.to_value(_u.km).T
            elif orbit == "l2":
                sun = get_body_barycentric("sun", when).xyz.to_value(_u.km).T
                away = observer - sun
                observer = observer + away * (_L2_DISTANCE_KM / np.linalg.norm(away, axis=1))[:, None]
            # Light time: the body where it was when the light now arriving left it (three iterations
            # converge far below a milliarcsecond for any body of the solar system).
            delay = np.zeros(t.size)
            for _ in range(3):
                position = get_body_barycentric(key, when - delay * _u.s).xyz.to_value(_u.km).T
                vector = position - observer
                delay = np.linalg.norm(vector, axis=1) / 299792.458
            distance = np.linalg.norm(vector, axis=1)
            v = vector @ _from_equatorial(frame).T
            theta = np.arccos(np.clip(v[:, 2] / distance, -1.0, 1.0))
            phi = np.mod(np.arctan2(v[:, 1], v[:, 0]), 2 * math.pi)

    if flux is not None:
        intensity = np.broadcast_to(np.asarray(flux, dtype=float), t.shape).copy()
        if not np.all(np.isfinite(intensity)):
            raise ValueError("flux: every value must be finite")
    else:
        a, b = BODIES[key]
        omega = math.pi * a * b / np.asarray(distance) ** 2
        if units.endswith("CMB"):
            rayleigh_jeans_to_cmb(frequency)  # a ValueError naming the frequency
        intensity = rayleigh_jeans_in(units, brightness_temperature, frequency or 0.0) * omega
    return SourceTrack(
        name if name is not None else key,
        (when.unix if unix_times else t).tolist(),
        np.asarray(theta, dtype=float).tolist(),
        np.asarray(phi, dtype=float).tolist(),
        intensity.tolist(),
        (fractions[0] * intensity).tolist(),
        (fractions[1] * intensity).tolist(),
        (fractions[2] * intensity).tolist(),
    )
