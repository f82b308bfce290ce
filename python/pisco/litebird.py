"""PISCO-VK inside litebird_sim (docs/python.md, "litebird_sim").

:func:`add_convolved_sky_to_observations` has the shape of litebird_sim's own function of that name
(``litebird_sim.beam_convolution``): observations, a sky and beams (one for all, or a dict by detector
or channel name), optional pointings and HWP, the TOD component to add into. Where litebird_sim takes
the sky and beams as spherical harmonics for its 4 pi convolution (ducc0), this one takes HEALPix maps
(``pisco.Sky`` or litebird_sim's ``HealpixMap``) and ``pisco.Beamsor`` beams, or litebird_sim's own
beam b_lm, and convolves in pixel space.

Conventions, those of litebird_sim: the detector pointing ``(theta, phi, psi)`` comes from
``Observation.get_pointings`` (ecliptic, rotated to galactic when the sky is galactic, as litebird_sim
does); ``psi`` is the orientation of the beam's frame and the detector's polarization angle
``pol_angle_rad`` is measured in it, so that the TOD is ``I + eta (Q cos 2a + U sin 2a)`` with
``a = psi + pol_angle_rad`` and ``eta = pol_efficiency``, litebird_sim's ``scan_map`` equation. A
``Beamsor`` is oriented in that frame, as litebird_sim's beam a_lm are.

Beams as litebird_sim's own function takes them: ``SphericalHarmonics`` b_lm (one for every detector, or
a dict by detector or channel name, as ``generate_gauss_beam_alms`` makes; or the observation's
``blms``). They are in the beam frame psi orients, the detector's polarization direction in them, ducc0's
convention: a detector at ``pol_angle_rad`` gets ``Beamsor.from_blm(b_lm exp(i m pol_angle_rad),
angle=pol_angle_rad)``, epsilon 0 and gain ``2 Omega~``, so that its TOD is litebird_sim's, ducc0's sum
over the coefficients.

Half-wave plates, as litebird_sim's MuellerConvolver takes them: the plate's angle per sample (from
the HWP object, ``IdealHWP(ang_speed_radpsec, start_angle_rad)``, or the observation's own) is
measured from the beam frame's x axis, each detector's plate is its ``mueller_hwp`` (a 4x4 Mueller
matrix) or the ideal one; an ideal plate gives ``a = psi + 2 hwp_angle - pol_angle_rad``, litebird_sim's
``scan_map`` angle with a plate.

Beams that turn with the plate (docs/changing.md): ``plate_beams`` gives detectors (by detector or
channel name, or all) beams simulated with the plate in them at plate angles
``pol_angle_rad + k plate_beams_period / N`` (measured as the plate's angle is, from the beam frame's x
axis), interpolated at each sample's plate angle; those detectors get no plate model.

Point sources (docs/sources.md): ``sources``, a list of ``pisco.SourceTrack``, are added to every
detector's TOD per sample, the beam evaluated at each source's direction exactly. Their directions are
in the sky's frame (galactic unless the sky says otherwise; ``pisco.planets.planet_track(frame=
"galactic", orbit="l2")`` gives a planet's), their times Unix seconds for an observation whose
``start_time`` is an astropy Time (``planet_track(..., unix_times=True)``), else on the clock of its
float ``start_time`` (``Observation.get_times()``).
"""

import logging

import numpy as np

from ._blm import detector_beam, resize_blm
from ._pisco import Beamsor, Engine, FocalPlane, HalfWavePlate, PlateBeams, Sky, SourceTrack

__all__ = ["add_convolved_sky_to_observations"]

_IDEAL = np.diag([1.0, 1.0, -1.0, -1.0])


def _as_sky(sky):
    """(pisco.Sky, coordinates or None) of a pisco.Sky or a litebird_sim HealpixMap."""
    if isinstance(sky, Sky):
        return sky, None
    values = getattr(sky, "values", None)
    if values is None:
        raise TypeError(f"sky: expected a pisco.Sky or a litebird_sim HealpixMap, got {type(sky).__name__}")
    values = np.asarray(values, dtype=np.float64)
    if values.ndim != 2:
        raise ValueError("sky: a HealpixMap of one frequency is expected (values of shape (nstokes, npix))")
    if getattr(sky, "nest", False):
        from ducc0.healpix import Healpix_Base

        nside = int(np.sqrt(values.shape[1] / 12))
        ring = Healpix_Base(nside, "RING").pix2nest(np.arange(values.shape[1]))
        values = values[:, ring]
    units = getattr(sky, "units", None)
    units = "K_CMB" if units is None else str(getattr(units, "name", units))
    return Sky.from_maps(np.ascontiguousarray(values), units=units), getattr(sky, "coordinates", None)


def _per_detector(value, obs, what):
    """The entry of `value` (an object, or a dict by detector or channel name) for each detector."""
    names = list(obs.name)
    if not isinstance(value, dict):
        return [value] * len(names)
    if all(n in value for n in names):
        return [value[n] for n in names]
    channels = list(getattr(obs, "channel", [None] * len(names)))
    if all(c in value for c in channels):
        return [value[c] for c in channels]
    raise ValueError(f"{what} dictionary keys do not match detector/channel names.")


def _plate_beams_of(plate_beams, obs, i):
    """Detector i's beams at the plate's angles (plate_beams: a list for every detector, or a dict by
    detector or channel name), or None."""
    if plate_beams is None:
        return None
    found = plate_beams
    if isinstance(plate_beams, dict):
        name = str(obs.name[i])
        channel = str(getattr(obs, "channel", [None] * (i + 1))[i])
        found = plate_beams.get(name, plate_beams.get(channel))
        if found is None:
            return None
    found = list(found) if hasattr(found, "__iter__") and not isinstance(found, (str, Beamsor)) else [found]
    if len(found) < 2 or not all(isinstance(b, Beamsor) for b in found):
        raise TypeError(f"plate_beams: detector {obs.name[i]}: expected a list of two or more pisco.Beamsor at the "
                        f"plate's angles, got {found!r}")
    return found


def _default_beam(obs, i, beam_rho_max):
    fwhm = np.radians(float(obs.fwhm_arcmin[i]) / 60.0)
    if not fwhm > 0:
        raise ValueError(f"detector {obs.name[i]}: no beam given and fwhm_arcmin is {obs.fwhm_arcmin[i]}")
    ellipticity = float(getattr(obs, "ellipticity", [1.0] * (i + 1))[i])
    rho_max = min(beam_rho_max * fwhm * np.sqrt(max(ellipticity, 1.0)), np.radians(89.0))
    if ellipticity == 1.0:
        return Beamsor.gaussian(fwhm, rho_max=rho_max)
    # litebird_sim: fwhm = sqrt(fwhm_max fwhm_min), ellipticity = fwhm_max / fwhm_min, the major axis at
    # psi_rad from the beam frame's x axis.
    psi_ell = float(obs.psi_rad[i])
    return Beamsor.elliptical_gaussian(fwhm * np.sqrt(ellipticity), fwhm / np.sqrt(ellipticity), psi_ell,
                                       rho_max=rho_max)


def _blm_beam(alms, name, zeta, rho_max, grid_step, convolution_params):
    """The beamsor of detector `name` at `zeta` from litebird_sim's SphericalHarmonics b_lm, kept to m <=
    convolution_params.mmax as litebird_sim keeps them."""
    values = np.asarray(alms.values)
    if values.ndim != 2 or values.shape[0] not in (1, 3):
        raise ValueError(f"beams: the b_lm of detector {name} must be of one frequency, T or T, E, B (values of "
                         f"shape (1 or 3, n)); got shape {values.shape}")
    lmax = int(alms.lmax)
    mmax = lmax if alms.mmax is None else int(alms.mmax)
    if convolution_params is not None and convolution_params.mmax < mmax:
        # litebird_sim resizes the beam to (lmax, mmax) of its parameters. Beyond lmax the beam meets no
        # sky power in its harmonic sum: only m is cut here.
        values = resize_blm(values, lmax, mmax, lmax, int(convolution_params.mmax))
        mmax = int(convolution_params.mmax)
    if not np.all(np.isfinite(values)):
        raise ValueError(f"beams: the b_lm of detector {name} are not finite")
    return detector_beam(values, lmax, mmax, zeta, rho_max, grid_step)


def _unix_or_own_times(obs):
    """The samples' times for sources: Unix seconds when the observation's start_time is an astropy Time,
    else its own float clock (Observation.get_times())."""
    import astropy.time

    if isinstance(obs.start_time, astropy.time.Time):
        return np.ascontiguousarray(obs.get_times(astropy_times=True).unix, dtype=np.float64)
    return np.ascontiguousarray(obs.get_times(), dtype=np.float64)


def _hwp_angle(obs, hwp, pointings_dtype):
    """The plate's angle per sample (float64, radians) as litebird_sim's own convolution takes it, or
    None without a plate: from `hwp` (its get_hwp_angle at the observation's start time and sampling
    rate), else from the observation's plate (its precomputed hwp_angle, or get_hwp_angle())."""
    if hwp is None:
        if not getattr(obs, "has_hwp", False):
            return None
        angle = getattr(obs, "hwp_angle", None)
        if angle is None:
            angle = obs.get_hwp_angle(pointings_dtype=pointings_dtype)
        return None if angle is None else np.ascontiguousarray(angle, dtype=np.float64)
    start = obs.start_time - obs.start_time_global
    start_s = start.to("s").value if hasattr(start, "to") else float(start)
    angle = np.empty(obs.n_samples, dtype=np.float64)
    hwp.get_hwp_angle(angle, start_s, 1.0 / obs.sampling_rate_hz)
    return angle


def _plate_mueller(obs, i, hwp):
    """Detector i's plate Mueller matrix M0: its ``mueller_hwp`` (a 4x4 matrix, as litebird_sim's
    MuellerConvolver takes it), else the ideal plate's for an ideal (or unspecified) HWP."""
    import litebird_sim as lbs

    name = obs.name[i]
    jones = getattr(obs, "jones_hwp", None)
    if jones is not None and jones[i] is not None:
        raise NotImplementedError(f"pisco.litebird: detector {name} has a Jones matrix (jones_hwp); give its plate "
                                  "as a 4x4 Mueller matrix (mueller_hwp)")
    mueller = getattr(obs, "mueller_hwp", None)
    m = None if mueller is None else mueller[i]
    if m is not None:
        if isinstance(m, dict) or np.shape(m) != (4, 4):
            raise NotImplementedError(f"pisco.litebird: detector {name}'s mueller_hwp is not one 4x4 matrix (a "
                                      "harmonic expansion of the plate is not supported)")
        m = np.asarray(m, dtype=np.float64)
        if not np.all(np.isfinite(m)):
            raise ValueError(f"detector {name}: mueller_hwp is not finite")
        try:  # a passive element's bounds (docs/physics.md, "Physical bounds on Mueller matrices")
            HalfWavePlate(m)
        except ValueError as exc:
            raise ValueError(f"detector {name}: mueller_hwp: {str(exc).removeprefix('mueller: ')}") from None
        return m
    plate = hwp if hwp is not None else getattr(obs, "hwp", None)
    if plate is None or isinstance(plate, lbs.IdealHWP):
        return _IDEAL
    raise ValueError(f"detector {name}: the HWP ({plate}) is not ideal, but the detector has no mueller_hwp")


def _observations_and_pointings(observations, pointings, lbs):
    """The observations as a list, and the pointings given for each (None: the observation's own)."""
    obs_list = [observations] if isinstance(observations, lbs.Observation) else list(observations)
    if pointings is None:
        return obs_list, [None] * len(obs_list)
    if isinstance(observations, lbs.Observation):
        return obs_list, [pointings]
    if not isinstance(pointings, list) or len(pointings) != len(obs_list):
        raise ValueError("pointings: give one pointing array per observation, as a list")
    return obs_list, pointings


def _source_list(sources):
    """The point sources as a list (empty for None), each a pisco.SourceTrack."""
    sources = list(sources) if sources is not None else []
    for k, track in enumerate(sources):
        if not isinstance(track, SourceTrack):
            raise TypeError(f"sources[{k}]: expected a pisco.SourceTrack, got {type(track).__name__}")
    return sources


class _Convolution:
    """One call of add_convolved_sky_to_observations: its arguments, and the skies and b_lm beams it has
    converted, each once for every observation and detector that shares it."""

    def __init__(self, *, sky, beams, hwp, component, pointings_dtype, coordinates, backend, device, beam_rho_max,
                 hwp_placement, convolution_params, beam_alms_rho_max, beam_alms_grid_step, plate_beams,
                 plate_beams_period, plate_beams_omega, sources):
        self.sky, self.beams, self.hwp, self.sources = sky, beams, hwp, sources
        self.component, self.pointings_dtype, self.coordinates = component, pointings_dtype, coordinates
        self.backend, self.device, self.hwp_placement = backend, device, hwp_placement
        self.beam_rho_max, self.convolution_params = beam_rho_max, convolution_params
        self.beam_alms_rho_max, self.beam_alms_grid_step = beam_alms_rho_max, beam_alms_grid_step
        self.plate_beams, self.plate_beams_period = plate_beams, plate_beams_period
        self.plate_beams_omega = plate_beams_omega
        self.converted = {}  # id of the caller's sky -> (pisco.Sky, coordinates)
        self.made = {}  # (id of the caller's b_lm, zeta) -> (their owner, pisco.Beamsor)

    def convert(self, s):
        """(pisco.Sky, coordinates) of the caller's sky s, converted the first time it is met."""
        if id(s) not in self.converted:
            self.converted[id(s)] = _as_sky(s)
        return self.converted[id(s)]

    def from_blm(self, alms, name, zeta):
        """The beamsor of litebird_sim b_lm at zeta, made the first time they are met at that angle."""
        key = (id(alms), zeta)
        if key not in self.made:
            self.made[key] = (alms, _blm_beam(alms, name, zeta, self.beam_alms_rho_max, self.beam_alms_grid_step,
                                              self.convolution_params))
        return self.made[key][1]

    def add_to(self, obs, ptg):
        """Adds the convolved sky (and the sources) to one observation's TOD; ptg: its pointings, or None."""
        from litebird_sim.coordinates import CoordinateSystem

        times = _unix_or_own_times(obs) if self.sources else None
        hwp_angle = _hwp_angle(obs, self.hwp, self.pointings_dtype)
        if hwp_angle is not None and not np.all(np.isfinite(hwp_angle)):
            raise ValueError("pisco.litebird: the plate's angles (hwp_angle) are not finite")
        tod = getattr(obs, self.component)
        n_det = tod.shape[0]
        skies = _per_detector(self.sky, obs, "Sky")
        det_beams = _per_detector(self.beams, obs, "Beam") if self.beams is not None else [None] * n_det
        # One engine per distinct sky, with the detectors that see it.
        groups = {}
        for i in range(n_det):
            groups.setdefault(id(skies[i]), []).append(i)
        for members in groups.values():
            pisco_sky, sky_coordinates = self.convert(skies[members[0]])
            frame = self.coordinates if self.coordinates is not None else sky_coordinates
            if frame is None:
                logging.warning("pisco.litebird: the sky's coordinates are unknown: assuming CoordinateSystem.Galactic")
                frame = CoordinateSystem.Galactic
            beam_list, fp = self._focal_plane(obs, members, det_beams, hwp_angle, n_det)
            with Engine(pisco_sky, beam_list, fp, backend=self.backend, device=self.device) as engine:
                self._convolve(engine, obs, ptg, members, frame, tod, times, hwp_angle)

    def _focal_plane(self, obs, members, det_beams, hwp_angle, n_det):
        """The engine's beams and focal plane for these detectors of the observation, in their order."""
        import litebird_sim as lbs

        beam_list, fp = [], FocalPlane()

        def beam_index(b):
            found = next((k for k, x in enumerate(beam_list) if x is b), None)
            if found is None:
                beam_list.append(b)
                found = len(beam_list) - 1
            return found

        for i in members:
            zeta = float(obs.pol_angle_rad[i])
            turning = _plate_beams_of(self.plate_beams, obs, i)
            if turning is not None:
                if hwp_angle is None:
                    raise ValueError(f"plate_beams: detector {obs.name[i]}'s beams turn with the plate, but the "
                                     "observation has no plate angles (give hwp, or an observation with a plate)")
                eta = float(getattr(obs, "pol_efficiency", np.ones(n_det))[i])
                epsilon = (1.0 - eta) / (1.0 + eta)
                # The plate's angle from the beam frame's x axis, its beams from the detector's axis.
                turns = PlateBeams([beam_index(b) for b in turning], period=self.plate_beams_period, gamma=zeta,
                                   omega=self.plate_beams_omega)
                fp.add(str(obs.name[i]), zeta=zeta, epsilon=epsilon, gain=2.0 / (1.0 + epsilon),
                       beam=turns.beams[0], plate_beams=turns)
                continue
            b = det_beams[i] if det_beams[i] is not None else _default_beam(obs, i, self.beam_rho_max)
            harmonic = isinstance(b, lbs.SphericalHarmonics)
            if harmonic:
                b = self.from_blm(b, obs.name[i], zeta)
            if not isinstance(b, Beamsor):
                raise TypeError(f"beams: expected pisco.Beamsor or litebird_sim.SphericalHarmonics for detector "
                                f"{obs.name[i]}, got {type(b).__name__}")
            found = beam_index(b)
            eta = float(getattr(obs, "pol_efficiency", np.ones(n_det))[i])
            epsilon = (1.0 - eta) / (1.0 + eta)
            gain = 2.0 / (1.0 + epsilon)
            if harmonic:
                # litebird_sim's TOD is ducc0's sum over the b_lm, which carry the polarization
                # efficiency: the engine's is gain / (2 Omega~) times it at epsilon 0.
                epsilon, gain = 0.0, 2.0 * b.omega_tilde
            plate = None
            if hwp_angle is not None:
                # The plate's angle is measured from the beam frame's x axis (psi), the detector's
                # polarization axis lies at pol_angle_rad from it: theta = hwp_angle - pol_angle_rad.
                plate = HalfWavePlate(_plate_mueller(obs, i, self.hwp), placement=self.hwp_placement, gamma=zeta)
            fp.add(str(obs.name[i]), zeta=zeta, epsilon=epsilon, gain=gain, beam=found, hwp=plate)
        return beam_list, fp

    def _convolve(self, engine, obs, ptg, members, frame, tod, times, hwp_angle):
        """Adds each of these detectors' convolved sky (and sources) into its row of the TOD, engine's
        detector k being members[k]."""
        from litebird_sim.coordinates import CoordinateSystem, rotate_coordinates_e2g

        sources = self.sources
        buffer = None
        for k, i in enumerate(members):
            if ptg is not None:
                p = np.asarray(ptg[i])
            elif getattr(obs, "pointing_matrix", None) is not None:
                p = np.asarray(obs.pointing_matrix[i])
            else:
                p, _ = obs.get_pointings(i, pointings_dtype=self.pointings_dtype, compute_hwp_angle=False)
            if frame == CoordinateSystem.Galactic:
                p = rotate_coordinates_e2g(p)
            theta, phi, psi = (np.ascontiguousarray(p[:, c], dtype=np.float64) for c in range(3))
            row = tod[i]
            if row.dtype == np.float64 and row.flags.c_contiguous and row.flags.writeable:
                engine.convolve(k, theta, phi, psi, out=row, accumulate=True, hwp_angle=hwp_angle)
                if sources:
                    engine.add_sources(k, times, sources, theta, phi, psi, out=row, hwp_angle=hwp_angle)
            else:
                buffer = engine.convolve(k, theta, phi, psi, out=buffer if buffer is not None and
                                         len(buffer) == len(theta) else None, hwp_angle=hwp_angle)
                if sources:
                    engine.add_sources(k, times, sources, theta, phi, psi, out=buffer, hwp_angle=hwp_angle)
                row += buffer.astype(row.dtype, copy=False)


def add_convolved_sky_to_observations(
    observations,
    sky,
    beams=None,
    pointings=None,
    hwp=None,
    component="tod",
    pointings_dtype=np.float64,
    coordinates=None,
    backend="auto",
    device="auto",
    beam_rho_max=2.5,
    hwp_placement="aperture",
    convolution_params=None,
    beam_alms_rho_max=np.radians(5.0),
    beam_alms_grid_step=0.0,
    plate_beams=None,
    plate_beams_period=np.pi,
    plate_beams_omega=0.0,
    sources=None,
):
    """Adds the beam-convolved sky to the TOD of litebird_sim observations, in pixel space.

    Parameters
    ----------
    observations : Observation or list of Observation
    sky : pisco.Sky, litebird_sim.HealpixMap, or a dict of them by detector or channel name
        HEALPix maps (I, Q, U[, V], COSMO convention); a HealpixMap's ``coordinates`` say its frame.
    beams : pisco.Beamsor, litebird_sim.SphericalHarmonics, a dict of them by detector or channel name, or None
        SphericalHarmonics: b_lm as litebird_sim's own function takes them (``beam_alms``, e.g. from
        ``generate_gauss_beam_alms``), in the beam frame psi orients with the detector's polarization in
        them; each detector gets them turned into its own Stokes basis (``pol_angle_rad``), epsilon 0
        and gain 2 Omega~, so that the TOD is litebird_sim's. None: the first observation's ``blms``
        where ``generate_gauss_beam_alms(..., store_in_observation=True)`` stored them (as litebird_sim
        does), else a Gaussian of each detector's ``fwhm_arcmin`` (elliptical with ``ellipticity`` and
        ``psi_rad``), summed out to ``beam_rho_max`` FWHM.
    pointings : array (n_det, n_samples, 3), a list of them (one per observation), or None
        None: the observations' own (``pointing_matrix``, or ``get_pointings``).
    hwp : litebird_sim.HWP or None
        The half-wave plate, as litebird_sim's own function takes it: its angle per sample comes from
        ``hwp.get_hwp_angle`` (litebird_sim's ``IdealHWP``: ``start_angle_rad`` plus
        ``ang_speed_radpsec`` times the time since the start of the simulation); None: the
        observations' own plate, if they have one. Each detector's plate is its ``mueller_hwp`` (a
        4x4 Mueller matrix), else ideal; its angle is measured from the axis psi orients, and the
        detector's polarization axis lies at ``pol_angle_rad`` from it (the plate's gamma), as in
        litebird_sim's MuellerConvolver and ``scan_map``.
    component : str
        The TOD attribute to add into (litebird_sim's ``tod`` by default).
    pointings_dtype : dtype
        The dtype of pointings computed on the fly.
    coordinates : litebird_sim.CoordinateSystem or None
        The frame of a pisco.Sky; None: the HealpixMap's, else galactic, as litebird_sim assumes.
    backend, device : str
        PISCO-VK's backend ('auto', 'cpu', 'simd', 'vulkan', 'cuda') and device.
    beam_rho_max : float
        Default beams are summed out to this many FWHM.
    hwp_placement : str
        Where the plate sits: 'aperture' (skyward of the optics, the default) or 'detector' (between
        the optics and the detector; four times the cost).
    convolution_params : litebird_sim.BeamConvolutionParameters or None
        As litebird_sim's: b_lm beyond its ``mmax`` are left out, as litebird_sim leaves them out (its
        other fields are its harmonic convolution's own).
    beam_alms_rho_max, beam_alms_grid_step : float
        Beams from b_lm are summed out to this radius (radians) and sampled with this step (radians; 0:
        ``Beamsor.from_blm``'s default, 0.75 / l_eff, FWHM / 16.8 for a Gaussian).
    plate_beams : list of pisco.Beamsor, a dict of them by detector or channel name, or None
        Beams that turn with the plate (docs/changing.md): each listed detector's beams with the plate in
        them at plate angles ``pol_angle_rad + k plate_beams_period / N``, interpolated at each sample's
        plate angle, in place of its beam and plate model. They need the plate's angles (``hwp`` or the
        observation's).
    plate_beams_period : float
        Their period (radians): pi for a half-wave plate.
    plate_beams_omega : float
        The solid angle (sr) their TOD is normalized by: 0, their mean Omega~ (the plate's mean
        transmission calibrated away); the beam's own Omega~ without the plate keeps the plate's losses,
        as the plate model does (``pisco.PlateBeams``' omega).
    sources : list of pisco.SourceTrack or None
        Point sources added per sample (docs/sources.md), in the sky's frame; their times Unix seconds
        when the observation's ``start_time`` is an astropy Time, else on its float clock.
    """
    import litebird_sim as lbs

    obs_list, ptg_list = _observations_and_pointings(observations, pointings, lbs)
    if hwp_placement not in ("aperture", "detector"):
        raise ValueError(f"hwp_placement: expected 'aperture' or 'detector', got {hwp_placement!r}")
    if beams is None and obs_list and getattr(obs_list[0], "blms", None) is not None:
        beams = obs_list[0].blms  # litebird_sim's own fallback: the b_lm stored in the observation
    call = _Convolution(
        sky=sky, beams=beams, hwp=hwp, component=component, pointings_dtype=pointings_dtype,
        coordinates=coordinates, backend=backend, device=device, beam_rho_max=beam_rho_max,
        hwp_placement=hwp_placement, convolution_params=convolution_params, beam_alms_rho_max=beam_alms_rho_max,
        beam_alms_grid_step=beam_alms_grid_step, plate_beams=plate_beams, plate_beams_period=plate_beams_period,
        plate_beams_omega=plate_beams_omega, sources=_source_list(sources))
    for obs, ptg in zip(obs_list, ptg_list):
        call.add_to(obs, ptg)
