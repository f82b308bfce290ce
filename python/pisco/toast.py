"""PISCO-VK inside TOAST 3: the operator :class:`PixelConvolve` (docs/python.md, "TOAST").

``PixelConvolve`` reads each observation's boresight quaternions (``boresight_radec`` by default)
and its focal plane, and writes or adds the beam-convolved sky into ``det_data``, as TOAST's own
``SimTotalconvolve`` and ``ScanHealpixMap`` do. The focal plane maps to PISCO-VK's detectors as
docs/formats.md ("TOAST focal planes") says, so that the TOD is in TOAST's calibration:
``I + eta (Q cos 2a + U sin 2a)``, ``eta = (1 - pol_leakage) / (1 + pol_leakage)``, ``a`` the
polarization angle of TOAST's detector quaternion, for a beam normalized to unit integral.

Beams: one ``pisco.Beamsor`` for every detector (``beam``), one per detector name (``beams``), the
frameworks' own harmonic beams (``beam_file`` / ``beam_file_dict``: healpy alm FITS files of b_lm, as
``SimTotalconvolve`` takes them), or, by default, a circular Gaussian of each detector's focal-plane
``fwhm`` summed out to ``beam_rho_max`` FWHM. One engine is set up per focal plane and reused by every
observation that shares it, until ``finalize()``.

Beam files: each detector's b_lm are those ``SimTotalconvolve`` (``dxx=False``) reads for it, with
the detector's polarization direction already in them, in the frame it hands ducc0 (psi - psi_pol +
pi): the antenna frame ``quat R_z(-psi_pol)`` turned by 180 deg. The detector's beamsor is
``Beamsor.from_blm(b_lm (-1)^m exp(i m psi_pol), angle=psi_pol)``: the pattern where the file has it,
its Stokes parameters in the detector's basis. The detector is calibrated as ``SimTotalconvolve`` with
``calibrate=True``: the file carries the polarization efficiency, so epsilon is 0, and the gain
``2 Omega~ / (1 + pol_leakage)`` gives its TOD, ``(1/2) (2 / (1 + pol_leakage))`` times ducc0's sum
over the coefficients.

Half-wave plates: an observation holding the shared ``hwp_angle`` (the plate's angle per sample in
the focal-plane frame, as ``SimSatellite`` and ``SimGround`` make it) puts a plate in front of every
detector: ideal, or the Mueller matrix ``hwp_mueller``, with each detector's ``gamma`` from the focal
plane (TOAST's own plate angle origin, the one its ``StokesWeights`` use), so that an ideal plate gives
TOAST's ``I + eta (Q cos 2b + U sin 2b)``, ``b = a + 2 (hwp_angle - gamma)``.

Beams that turn with the plate (docs/changing.md): ``plate_beams`` gives a detector, by name, a list of
``pisco.Beamsor`` simulated with the plate in them at plate angles ``gamma + k plate_beams_period / N``
from its focal-plane ``gamma``; at each sample they are interpolated in ``hwp_angle``, and that detector
gets no plate model (the plate is in its beams). Such detectors need the observation's ``hwp_angle``.

Point sources (docs/sources.md): ``sources``, a list of ``pisco.SourceTrack`` (fixed, moving or
flaring; ``pisco.planets.planet_track`` gives the planets'), are added to every detector's TOD per
sample, each detector's beam evaluated at each source's direction, exactly; the tracks' times are on
the observation's clock (the shared ``times``, Unix seconds), their directions in the frame of the
boresight quaternions (ICRS for ``boresight_radec``: ``planet_track(frame="equatorial")``).
"""

import os

import numpy as np
import traitlets
from astropy import units as u

from toast.observation import default_values as defaults
from toast.ops.operator import Operator
from toast.timing import function_timer
from toast.traits import Bool, Dict, Float, Instance, Int, List, Unicode, Unit, trait_docs
from toast.utils import Logger

from ._blm import detector_beam, read_blm_file, resize_blm
from ._focal_plane import focal_plane_from_toast
from ._pisco import Beamsor, Engine, FocalPlane, HalfWavePlate, PlateBeams, Sky, SourceTrack

__all__ = ["PixelConvolve"]


class _MuellerList(List):
    """A List trait that also takes a numpy array or a tuple (a 4x4 matrix or 16 numbers)."""

    _cast_types = (tuple, np.ndarray)

    def validate(self, obj, value):
        if isinstance(value, np.ndarray):
            value = value.tolist()
        return super().validate(obj, value)


def _mueller_matrix(value):
    """A (4, 4) float64 array from 16 numbers (row by row) or 4 rows of 4; ValueError otherwise."""
    try:
        m = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        raise ValueError(f"hwp_mueller: expected 16 numbers or a 4x4 matrix, got {value!r}") from None
    if m.size != 16 or m.shape not in ((16,), (4, 4)):
        raise ValueError(f"hwp_mueller: expected 16 numbers (row by row) or a 4x4 matrix, got shape {m.shape}")
    if not np.all(np.isfinite(m)):
        raise ValueError("hwp_mueller: the Mueller matrix must be finite")
    m = m.reshape(4, 4)
    try:  # a passive element's bounds (docs/physics.md, "Physical bounds on Mueller matrices")
        HalfWavePlate(m)
    except ValueError as exc:
        raise ValueError(f"hwp_mueller: {str(exc).removeprefix('mueller: ')}") from None
    return m


def _astropy_unit(units):
    """The astropy unit of a sky's units string ('K_CMB', 'uK_CMB', 'K', ...), or None."""
    name = units.strip()
    for suffix in ("_CMB", "_RJ", "CMB", "RJ"):
        if name.endswith(suffix):
            name = name[: -len(suffix)]
            break
    try:
        return u.Unit(name)
    except ValueError:
        return None


@trait_docs
class PixelConvolve(Operator):
    """Beam-convolved detector timestreams from PISCO-VK's pixel-space convolution."""

    API = Int(0, help="Internal interface version for this operator")

    sky = Instance(klass=Sky, allow_none=True, help="The sky, a pisco.Sky (or give sky_file)")

    sky_file = Unicode(
        None, allow_none=True, help="HEALPix FITS map (I; I, Q, U; or I, Q, U, V) read when sky is None"
    )

    beam = Instance(klass=Beamsor, allow_none=True, help="One pisco.Beamsor for every detector")

    beams = Dict({}, help="pisco.Beamsor by detector name (when beam is None)")

    beam_rho_max = Float(
        2.5, help="Without beam or beams: Gaussian beams of the focal plane's fwhm, summed out to this many FWHM"
    )

    beam_file = Unicode(
        None,
        allow_none=True,
        help="healpy alm FITS file of each detector's b_lm (SimTotalconvolve's beam_file: {detector} and {mc} "
        "are replaced by the detector's name and mc)",
    )

    beam_file_dict = Dict({}, help="b_lm file by detector name, taking precedence over beam_file")

    beam_file_rho_max = Float(np.radians(5.0), help="Beams from b_lm files are summed out to this radius (radians)")

    beam_file_grid_step = Float(
        0.0, help="Beams from b_lm files are sampled with this step (radians); 0: 0.75 / l_eff (FWHM / 16.8 for a "
        "Gaussian), Beamsor.from_blm's"
    )

    beam_file_mmax = Int(-1, help="Beams from b_lm files keep m <= this (SimTotalconvolve's beammmax); -1: all")

    normalize_beam = Bool(
        False, help="Beams from b_lm files: scaled to b_00 = 1 / (2 sqrt(pi)), as SimTotalconvolve's normalize_beam"
    )

    mc = Int(None, allow_none=True, help="Monte Carlo index for the {mc} field of beam_file")

    plate_beams = Dict(
        {}, help="By detector name, a list of pisco.Beamsor with the plate in them at plate angles gamma + k "
        "plate_beams_period / N (gamma the focal plane's): the detector's beam turns with the plate"
    )

    plate_beams_period = Float(np.pi, help="The plate's period for plate_beams (radians): pi for a half-wave plate")

    plate_beams_omega = Float(
        0.0, help="The solid angle (sr) plate_beams' TOD is normalized by: 0, their mean Omega~; the beam's own "
        "Omega~ without the plate keeps the plate's losses (pisco.PlateBeams' omega)"
    )

    sources = List([], help="pisco.SourceTrack point sources added per sample (times on the shared times' clock)")

    times = Unicode(defaults.times, help="Observation shared key for the samples' times (Unix seconds), for sources")

    boresight = Unicode(defaults.boresight_radec, help="Observation shared key for boresight quaternions")

    hwp_angle = Unicode(
        defaults.hwp_angle,
        allow_none=True,
        help="Observation shared key for the HWP angle: an observation holding it gets a plate in front of "
        "every detector, with the focal plane's gamma; None ignores it (no plate)",
    )

    hwp_mueller = _MuellerList(
        [],
        help="The plate's Mueller matrix at angle 0 (16 numbers row by row, or 4 rows of 4, kept as 16 numbers; "
        "fast axis along the detector's polarization axis); empty: the ideal plate diag(1, 1, -1, -1)",
    )

    hwp_placement = Unicode(
        "aperture", help="Where the plate sits: 'aperture' (skyward of the optics) or 'detector' (before the "
        "detector, after the optics: four times the cost)"
    )

    det_data = Unicode(defaults.det_data, help="Observation detdata key for the convolved timestreams")

    det_data_units = Unit(defaults.det_data_units, help="Output units if creating detector data")

    det_mask = Int(defaults.det_mask_invalid, help="Bit mask value for per-detector flagging")

    view = Unicode(None, allow_none=True, help="Use this view of the data in all observations")

    zero = Bool(False, help="If True, overwrite det_data instead of adding into it")

    backend = Unicode("auto", help="PISCO-VK backend: 'auto', 'cpu', 'simd', 'vulkan' or 'cuda'")

    device = Unicode("auto", help="Device index or part of its name ('auto': the best)")

    @traitlets.validate("beam_rho_max")
    def _check_beam_rho_max(self, proposal):
        if not proposal["value"] > 0:
            raise traitlets.TraitError("beam_rho_max must be positive")
        return proposal["value"]

    @traitlets.validate("beam_file_rho_max")
    def _check_beam_file_rho_max(self, proposal):
        if not 0 < proposal["value"] < np.pi / 2:
            raise traitlets.TraitError("beam_file_rho_max must lie in (0, pi / 2) radians")
        return proposal["value"]

    @traitlets.validate("beam_file_grid_step")
    def _check_beam_file_grid_step(self, proposal):
        if not proposal["value"] >= 0:
            raise traitlets.TraitError("beam_file_grid_step cannot be negative")
        return proposal["value"]

    @traitlets.validate("mc")
    def _check_mc(self, proposal):
        if proposal["value"] is not None and proposal["value"] < 0:
            raise traitlets.TraitError("mc cannot be negative")
        return proposal["value"]

    @traitlets.validate("hwp_mueller")
    def _check_hwp_mueller(self, proposal):
        if len(proposal["value"]) == 0:
            return []
        try:
            return [float(x) for x in _mueller_matrix(proposal["value"]).ravel()]
        except ValueError as exc:
            raise traitlets.TraitError(str(exc)) from None

    @traitlets.validate("hwp_placement")
    def _check_hwp_placement(self, proposal):
        if proposal["value"] not in ("aperture", "detector"):
            raise traitlets.TraitError(f"hwp_placement must be 'aperture' or 'detector', not {proposal['value']!r}")
        return proposal["value"]

    @traitlets.validate("plate_beams")
    def _check_plate_beams(self, proposal):
        for name, beams in proposal["value"].items():
            if isinstance(beams, (str, Beamsor)) or not hasattr(beams, "__iter__"):
                raise traitlets.TraitError(f"plate_beams['{name}'] is not a list of pisco.Beamsor")
            beams = list(beams)
            if len(beams) < 2 or not all(isinstance(b, Beamsor) for b in beams):
                raise traitlets.TraitError(f"plate_beams['{name}']: expected two or more pisco.Beamsor at the plate's "
                                           f"angles, got {beams!r}")
        return proposal["value"]

    @traitlets.validate("plate_beams_period")
    def _check_plate_beams_period(self, proposal):
        if not (np.isfinite(proposal["value"]) and proposal["value"] > 0):
            raise traitlets.TraitError("plate_beams_period must be positive (pi for a half-wave plate)")
        return proposal["value"]

    @traitlets.validate("sources")
    def _check_sources(self, proposal):
        for i, track in enumerate(proposal["value"]):
            if not isinstance(track, SourceTrack):
                raise traitlets.TraitError(f"sources[{i}] is not a pisco.SourceTrack")
        return proposal["value"]

    @traitlets.validate("beams")
    def _check_beams(self, proposal):
        for name, beam in proposal["value"].items():
            if not isinstance(beam, Beamsor):
                raise traitlets.TraitError(f"beams['{name}'] is not a pisco.Beamsor")
        return proposal["value"]

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self._engines = {}
        self._sky = None
        self._blm_files = {}  # path -> (b_lm, lmax, mmax)
        self._file_beams = {}  # (path, zeta, rho_max, grid_step, mmax, normalize) -> (beamsor, gain factor)

    def _get_sky(self):
        if self.sky is not None:
            return self.sky
        if self.sky_file is None:
            raise RuntimeError("PixelConvolve: give sky (a pisco.Sky) or sky_file")
        if self._sky is None or self._sky[0] != self.sky_file:
            self._sky = (self.sky_file, Sky.read_fits(self.sky_file))
        return self._sky[1]

    def _beams_for(self, focalplane, names):
        """The engine's beam list and each detector's index into it."""
        if self.beam is not None:
            return [self.beam], [0] * len(names)
        if len(self.beams) > 0:
            missing = [n for n in names if n not in self.beams]
            if missing:
                raise RuntimeError(f"PixelConvolve: beams has no beam for detectors {missing}")
            unique, index = [], []
            for n in names:
                b = self.beams[n]
                found = next((i for i, x in enumerate(unique) if x is b), None)
                if found is None:
                    unique.append(b)
                    found = len(unique) - 1
                index.append(found)
            return unique, index
        table = focalplane.detector_data
        if "fwhm" not in table.colnames:
            raise RuntimeError("PixelConvolve: no beam, no beams, and the focal plane has no fwhm column")
        fwhm = {str(n): float(u.Quantity(f).to_value(u.rad)) for n, f in zip(table["name"], table["fwhm"])}
        widths = sorted({fwhm[n] for n in names})
        beams = [Beamsor.gaussian(w, rho_max=min(self.beam_rho_max * w, np.radians(89.0))) for w in widths]
        return beams, [widths.index(fwhm[n]) for n in names]

    def _beam_file_of(self, name):
        """The b_lm file of detector `name`, picked as SimTotalconvolve picks it."""
        if name in self.beam_file_dict:
            return os.fspath(self.beam_file_dict[name])
        if self.beam_file is None:
            raise RuntimeError(f"PixelConvolve: detector {name} has no beam file: it is not in beam_file_dict "
                               "and beam_file is not set")
        try:
            return self.beam_file.format(detector=name, mc=self.mc)
        except (KeyError, IndexError, ValueError) as exc:
            raise RuntimeError(f"PixelConvolve: beam_file '{self.beam_file}' for detector {name}: {exc!r} (the "
                               "fields are {detector} and {mc})") from None

    def _file_beam(self, name, path, zeta):
        """(beamsor, gain factor) of detector `name` at `zeta` from the b_lm file `path`, cached."""
        key = (path, zeta, self.beam_file_rho_max, self.beam_file_grid_step, self.beam_file_mmax, self.normalize_beam)
        if key not in self._file_beams:
            if path not in self._blm_files:
                if not os.path.isfile(path):
                    raise RuntimeError(f"PixelConvolve: detector {name}: the beam file {path} does not exist")
                try:
                    self._blm_files[path] = read_blm_file(path)
                except (OSError, ValueError, KeyError, IndexError, TypeError) as exc:
                    raise RuntimeError(f"PixelConvolve: detector {name}: cannot read the beam file {path}: "
                                       f"{exc}") from None
            blm, lmax, mmax = self._blm_files[path]
            if 0 <= self.beam_file_mmax < mmax:
                blm = resize_blm(blm, lmax, mmax, lmax, self.beam_file_mmax)
                mmax = self.beam_file_mmax
            factor = 1.0
            if self.normalize_beam:
                b00 = blm[0, 0].real
                if not b00 > 0:
                    raise RuntimeError(f"PixelConvolve: detector {name}: normalize_beam, but b_00 of {path} is {b00}")
                factor = 1.0 / (2 * np.sqrt(np.pi) * b00)
            try:
                # SimTotalconvolve gives ducc0 the angle psi - psi_pol + pi: its beam frame is the
                # antenna frame (quat R_z(-psi_pol)) turned by 180 deg.
                beam = detector_beam(blm, lmax, mmax, zeta, self.beam_file_rho_max, self.beam_file_grid_step,
                                     half_turn=True)
            except RuntimeError as exc:
                raise RuntimeError(f"PixelConvolve: detector {name}: the beam file {path}: {exc}") from None
            self._file_beams[key] = (beam, factor)
        return self._file_beams[key]

    def _with_file_beams(self, focalplane, fp):
        """(beams, focal plane, {name: why it has no beam}): the engine's beams from each detector's b_lm
        file, turned by its zeta, and the detectors of `fp` that have one, calibrated as SimTotalconvolve
        calibrates (calibrate=True): epsilon 0 (the file carries the polarization efficiency), gain
        2 Omega~ / (1 + pol_leakage). A detector without a file is left out, and fails only if convolved
        (SimTotalconvolve needs files for the detectors it convolves only)."""
        table = focalplane.detector_data
        leakage = {str(n): 0.0 for n in table["name"]}
        if "pol_leakage" in table.colnames:
            leakage = {str(n): float(e) for n, e in zip(table["name"], table["pol_leakage"])}
        beams, out, missing = [], FocalPlane(), {}
        for d in fp.detectors:
            try:
                beam, factor = self._file_beam(d.name, self._beam_file_of(d.name), d.zeta)
            except RuntimeError as exc:
                missing[d.name] = str(exc)
                continue
            found = next((i for i, x in enumerate(beams) if x is beam), None)
            if found is None:
                beams.append(beam)
                found = len(beams) - 1
            d.beam = found
            d.epsilon = 0.0
            # SimTotalconvolve: (1/2) (2 / (1 + epsilon)) times ducc0's sum; the engine: gain / (2 Omega~) times it.
            d.gain = 2.0 * beam.omega_tilde * factor / (1.0 + leakage[d.name])
            out.add(d)
        return beams, out, missing

    def _with_plate_beams(self, beams, fp, plates):
        """The engine's beams and focal plane with plate_beams' detectors given their beams at the plate's
        angles, from the plate gamma the focal plane gives them, and no plate model."""
        unknown = [n for n in self.plate_beams if n not in fp.names]
        if unknown:
            raise RuntimeError(f"PixelConvolve: plate_beams names detectors the focal plane does not hold: {unknown}")
        if not plates:
            raise RuntimeError("PixelConvolve: plate_beams need the observation's plate angle "
                               f"('{self.hwp_angle}' in its shared data)")
        beams = list(beams)
        out = FocalPlane()
        for d in fp.detectors:
            if d.name in self.plate_beams:
                first = len(beams)
                beams.extend(self.plate_beams[d.name])
                d.plate_beams = PlateBeams(list(range(first, len(beams))), period=self.plate_beams_period,
                                           gamma=d.hwp.gamma, omega=self.plate_beams_omega)
                d.hwp = None
            out.add(d)
        return beams, out

    def _plate(self):
        """The plate model (its gamma set per detector from the focal plane)."""
        mueller = _mueller_matrix(self.hwp_mueller) if self.hwp_mueller else None
        return HalfWavePlate(mueller, placement=self.hwp_placement)

    def _engine_for(self, focalplane, plates):
        """(engine, {name: detector index}, {name: why it has no beam}) for a TOAST focal plane, with or
        without plates, set up on first use."""
        # With plates, the plate model is part of the key: traits changed between calls take effect.
        model = (tuple(_mueller_matrix(self.hwp_mueller).ravel()) if self.hwp_mueller else None,
                 self.hwp_placement) if plates else None
        # And the plate beams, by the beams' identities.
        turning = (tuple(sorted((n, tuple(id(b) for b in bs)) for n, bs in self.plate_beams.items())),
                   self.plate_beams_period, self.plate_beams_omega)
        key = (id(focalplane), model, turning)
        if key not in self._engines:
            names = [str(n) for n in focalplane.detector_data["name"]]
            plate = self._plate() if plates else None
            missing = {}
            if self.beam_file is not None or len(self.beam_file_dict) > 0:
                if self.beam is not None or len(self.beams) > 0:
                    raise RuntimeError("PixelConvolve: give beam or beams, or beam_file / beam_file_dict, not both")
                beams, fp, missing = self._with_file_beams(focalplane, focal_plane_from_toast(focalplane, hwp=plate))
                if len(fp) == 0:
                    raise RuntimeError(next(iter(missing.values())))
                names = fp.names
            else:
                beams, index = self._beams_for(focalplane, names)
                fp = focal_plane_from_toast(focalplane, beam=index, hwp=plate)
            if len(self.plate_beams) > 0:
                beams, fp = self._with_plate_beams(beams, fp, plates)
            engine = Engine(self._get_sky(), beams, fp, backend=self.backend, device=self.device)
            # The focal plane is held too, so that its id cannot be reused by another while cached.
            self._engines[key] = (engine, {n: i for i, n in enumerate(names)}, missing, focalplane)
            log = Logger.get()
            log.debug(f"PixelConvolve: {len(names)} detectors on {engine.backend} ({engine.device})"
                      + (", with half-wave plates" if plates else ""))
        engine, index, missing, _ = self._engines[key]
        return engine, index, missing

    @function_timer
    def _exec(self, data, detectors=None, **kwargs):
        sky = self._get_sky()
        scale_unit = _astropy_unit(sky.units)
        for ob in data.obs:
            dets = ob.select_local_detectors(detectors, flagmask=self.det_mask)
            if len(dets) == 0:
                continue
            plates = self.hwp_angle is not None and self.hwp_angle in ob.shared
            if self.boresight not in ob.shared:
                raise RuntimeError(f"PixelConvolve: observation {ob.name} has no shared '{self.boresight}'")
            ob.detdata.ensure(self.det_data, detectors=dets, create_units=self.det_data_units)
            out_units = ob.detdata[self.det_data].units
            scale = 1.0
            if scale_unit is not None and out_units is not None:
                try:
                    scale = float((1.0 * scale_unit).to_value(out_units))
                except u.UnitConversionError:
                    scale = 1.0
            engine, index, missing = self._engine_for(ob.telescope.focalplane, plates)
            for det in dets:
                if det in missing:
                    raise RuntimeError(missing[det])
            views = ob.view[self.view]
            for vw in range(len(views)):
                quats = views.shared[self.boresight][vw]
                quats = np.ascontiguousarray(quats, dtype=np.float64)
                if len(quats) == 0:
                    continue
                angles = None
                if plates:
                    angles = np.ascontiguousarray(views.shared[self.hwp_angle][vw], dtype=np.float64)
                    if not np.all(np.isfinite(angles)):
                        bad = int(np.argmin(np.isfinite(angles)))
                        raise ValueError(f"PixelConvolve: observation {ob.name}: '{self.hwp_angle}' is not finite "
                                         f"(view sample {bad}: {angles[bad]})")
                times = None
                if len(self.sources) > 0:
                    if self.times not in ob.shared:
                        raise RuntimeError(f"PixelConvolve: observation {ob.name} has no shared '{self.times}', "
                                           "which sources need")
                    times = np.ascontiguousarray(views.shared[self.times][vw], dtype=np.float64)
                # The detectors whose rows take the TOD as it is, in one call: the boresight checked
                # once, and on a GPU staged once a slot rather than once a detector.
                direct = []
                for det in dets:
                    out = views.detdata[self.det_data][vw][det]
                    if scale == 1.0 and out.dtype == np.float64 and out.flags.c_contiguous and out.flags.writeable:
                        direct.append(det)
                if direct:
                    rows = [views.detdata[self.det_data][vw][det] for det in direct]
                    engine.convolve_detectors([index[det] for det in direct], boresight_quats=quats, out=rows,
                                              accumulate=not self.zero, hwp_angle=angles)
                    if times is not None:
                        for det, out in zip(direct, rows):
                            engine.add_sources(index[det], times, self.sources, boresight_quats=quats, out=out,
                                               hwp_angle=angles)
                taken = set(direct)
                for det in dets:
                    if det not in taken:
                        out = views.detdata[self.det_data][vw][det]
                        tod = engine.convolve(index[det], boresight_quats=quats, hwp_angle=angles)
                        if times is not None:
                            engine.add_sources(index[det], times, self.sources, boresight_quats=quats, out=tod,
                                               hwp_angle=angles)
                        if self.zero:
                            out[:] = scale * tod
                        else:
                            out[:] += scale * tod

    def _finalize(self, data, **kwargs):
        for engine, *_ in self._engines.values():
            engine.close()
        self._engines = {}
        self._blm_files = {}
        self._file_beams = {}

    def _requires(self):
        req = {"shared": [self.boresight], "detdata": [], "intervals": []}
        if len(self.sources) > 0:
            req["shared"].append(self.times)
        if not self.zero:
            req["detdata"].append(self.det_data)
        if self.view is not None:
            req["intervals"].append(self.view)
        return req

    def _provides(self):
        return {"detdata": [self.det_data]}
