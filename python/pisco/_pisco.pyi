"""PISCO-VK's C++ library: pixel-space beam convolution (see the package pisco)."""

import os
from collections.abc import Callable, Iterable, Mapping, Sequence
from typing import Any, Literal

import numpy
from numpy.typing import ArrayLike, NDArray

Float64Array = NDArray[numpy.float64]
UnseenPolicy = Literal["error", "zero", "flag"]

__version__: str
deg: float
unseen: float
# How far from 1 the norm of a rotation quaternion may be: offsets and boresight quaternions further
# from unit norm raise ValueError (within it, the rounding is normalized away).
unit_quat_tolerance: float
# The relative tolerance of the physical bounds on Mueller matrices (docs/physics.md, "Physical bounds
# on Mueller matrices"): a plate's M0 and a beam's constant matrix beyond them raise ValueError.
mueller_tolerance: float

class Error(RuntimeError):
    """An error of the C++ library (pisco::Error), carrying its message; raised as one of its subclasses."""

    kind: str | None
    """What went wrong: "input", "unavailable", "device", "io" or "internal" (None on Error itself)."""

class InputError(Error):
    """A bad argument, file content or configuration."""

class UnavailableError(Error):
    """A backend, device, driver or library absent from this machine."""

class DeviceError(Error):
    """A device that failed while working: out of memory, lost, or a driver error."""

class FileError(Error):
    """A file that could not be opened, read, written or renamed."""

class InternalError(Error):
    """A broken invariant of the library itself: a bug to report."""

class BackendInfo:
    """A backend the library knows, whether it runs here and what it can do."""

    @property
    def name(self) -> str: ...
    @property
    def available(self) -> bool: ...
    @property
    def detail(self) -> str:
        """The device found, or why the backend is unavailable."""

    @property
    def capabilities(self) -> dict[str, bool | int]:
        """What it can do: float64 (every operation in float64), plates, adjoint, worker_threads (its own host threads: `threads` applies), normal (a one-pass normal on its float32 path), device_memory (bytes of the device auto picks; 0: host memory)."""

def devices() -> list[BackendInfo]:
    """The backends the library knows ('cpu', 'simd', 'vulkan', 'cuda'), built or not, with availability and device or reason."""

def offset_quat(xi: float, eta: float, gamma: float) -> Float64Array:
    """The offset quaternion (x, y, z, w) of focal-plane coordinates (xi, eta, gamma), radians."""

def quat_from_pointing(theta: float, phi: float, psi: float) -> Float64Array:
    """The rotation R_z(phi) R_y(theta) R_z(psi) (TOAST's ISO angles) as (x, y, z, w)."""

def quat_to_pointing(q: ArrayLike) -> tuple[float, float, float]:
    """The angles (theta, phi, psi) of a rotation (x, y, z, w)."""

def valid_nside(nside: int) -> bool:
    """Whether nside is a power of two in [1, 8192]."""

def ground_sky(nside: int, value: float, horizon: Sequence[float] = ..., width: float = 0.0, units: str = "uK_CMB") -> Sky:
    """A ground in the horizon frame: `value` below the horizon (elevations at azimuths 2 pi k / N), 0 above."""

def rayleigh_jeans_in(units: str, kelvin: float, frequency_ghz: float = 0.0) -> float:
    """A Rayleigh-Jeans brightness temperature in K_RJ, uK_RJ, K_CMB or uK_CMB (at frequency_ghz)."""

def ang2pix(nside: int, theta: float, phi: float) -> int:
    """The RING pixel containing (theta, phi)."""

class Sky:
    """A polarized sky: HEALPix I, Q, U, V maps (RING ordering, COSMO polarization convention).

    Sky(nside, units='K_CMB') is a sky of zeros; Sky.from_maps and Sky.read_fits fill one.
    The maps I, Q, U, V are writable numpy views of the sky's own storage (no copy).
    """

    def __init__(self, nside: int, units: str = "K_CMB") -> None: ...
    @staticmethod
    def from_maps(maps: Float64Array | Sequence[Float64Array], units: str = "K_CMB") -> Sky:
        """A sky from k = 1, 3 or 4 RING maps (I; I, Q, U; I, Q, U, V), copied into the sky."""
    @staticmethod
    def read_fits(path: str | os.PathLike[str], unseen: UnseenPolicy = "error") -> Sky:
        """Reads a HEALPix FITS map (1, 3 or 4 columns); NESTED becomes RING, IAU becomes COSMO.

        unseen: UNSEEN pixels (a masked map) raise pisco.Error ('error'), are set to 0 ('zero') or
        are kept as UNSEEN for an Engine made with unseen='flag' ('flag').
        """
    def unseen_pixels(self) -> NDArray[numpy.int64]:
        """The RING indices of the pixels UNSEEN in any Stokes map, ascending."""
    def zero_unseen(self) -> int:
        """Sets the UNSEEN values to 0; returns the number of pixels changed."""
    def write_fits(self, path: str | os.PathLike[str]) -> None:
        """Writes I, Q, U, V as a HEALPix FITS file (RING, COSMO), atomically."""
    @property
    def nside(self) -> int: ...
    @property
    def npix(self) -> int: ...
    @property
    def pixel_area(self) -> float:
        """4 pi / npix, steradians."""
    @property
    def units(self) -> str: ...
    @units.setter
    def units(self, value: str, /) -> None: ...
    @property
    def I(self) -> Float64Array: ...
    @property
    def Q(self) -> Float64Array: ...
    @property
    def U(self) -> Float64Array: ...
    @property
    def V(self) -> Float64Array: ...

class Beamsor:
    """A field of 4x4 Mueller matrices over the beam's directions, sampled out to rho_max (radians)."""

    @staticmethod
    def gaussian(
        fwhm: float,
        rho_max: float = ...,
        grid_step: float = 0.0,
        cross_polar: float = 0.0,
        cross_polar_pattern: str = "uniform",
        mueller: ArrayLike | None = None,
        sidelobes: float | tuple[float, ...] | None = None,
        far_sidelobe: tuple[float, ...] | None = None,
    ) -> Beamsor:
        """A circular Gaussian beam of full width at half maximum `fwhm`, summed out to rho_max (5 deg)."""
    @staticmethod
    def elliptical_gaussian(
        fwhm_x: float,
        fwhm_y: float,
        angle: float = 0.0,
        rho_max: float = ...,
        grid_step: float = 0.0,
        cross_polar: float = 0.0,
        cross_polar_pattern: str = "uniform",
        mueller: ArrayLike | None = None,
        sidelobes: float | tuple[float, ...] | None = None,
        far_sidelobe: tuple[float, ...] | None = None,
    ) -> Beamsor:
        """fwhm_x along the direction `angle` (from theta' towards phi'), fwhm_y across it."""
    @staticmethod
    def from_grasp(
        path: str | os.PathLike[str],
        rho_max: float = ...,
        grid_step: float = 0.0,
        set: int | None = None,
        angle: float = 0.0,
        sidelobes: float | tuple[float, ...] | None = None,
    ) -> Beamsor:
        """A TICRA GRASP far field (.grd or .cut, ICOMP 3), its x axis at `angle` from theta'."""
    @staticmethod
    def from_blm(
        blm: str | os.PathLike[str] | ArrayLike,
        rho_max: float = ...,
        grid_step: float = 0.0,
        angle: float = 0.0,
        lmax: int | None = None,
        mmax: int | None = None,
        sidelobes: float | tuple[float, ...] | None = None,
    ) -> Beamsor:
        """Harmonic beam coefficients (healpy alm FITS file or (T[, E, B]) arrays), ducc0's convention."""
    @staticmethod
    def from_field(
        field: Callable[[float, float], ArrayLike],
        rho_max: float,
        grid_step: float,
        description: str = "python field",
        feature_scale: float = 0.0,
        radial: bool = False,
        sidelobes: float | tuple[float, ...] | None = None,
    ) -> Beamsor:
        """Any beam: field(rho, sigma) returns the (unnormalized) 4x4 Mueller matrix."""
    @staticmethod
    def read_fits(path: str | os.PathLike[str], rho_max: float, grid_step: float = 0.0) -> Beamsor:
        """Reads one of the paper's HEALPix beamsor files (columns B_TT, B_QT, ...)."""
    def write_fits(self, path: str | os.PathLike[str], nside: int) -> None: ...
    @property
    def sidelobes(self) -> Beamsor | None:
        """A split beam's outer part (out to the whole beam's rho_max), else None."""
    @property
    def sidelobe_band_limit(self) -> int: ...
    @property
    def rho_max(self) -> float: ...
    @property
    def is_radial(self) -> bool: ...
    @property
    def grid_size(self) -> int: ...
    @property
    def grid_step(self) -> float: ...
    @property
    def omega_tilde(self) -> float:
        """The integral of B_TT over the cap, steradians."""
    @property
    def description(self) -> str: ...
    def element(self, row: int, col: int) -> Float64Array | None:
        """The grid values of Mueller element (row, col), a read-only view; None for a zero element."""
    def at(self, x: float, y: float) -> Float64Array:
        """The interpolated 4x4 Mueller matrix at orthographic (x, y)."""

class HalfWavePlate:
    """A half-wave plate (or any rotating Mueller element) in front of a detector.

    mueller: M0, the 4x4 Mueller matrix with the fast axis along the detector's polarization axis
    (None: the ideal plate diag(1, 1, -1, -1)); placement: 'aperture' or 'detector'; gamma: the
    detector's polarization angle in the focal-plane frame (radians, TOAST's ``gamma``). At plate
    angle h the plate is R(-theta) M0 R(theta), theta = h - gamma.
    """

    def __init__(self, mueller: ArrayLike | None = None, placement: str = "aperture", gamma: float = 0.0) -> None:
        """ValueError naming `mueller` for a matrix that is not finite or not a passive element's: M00 <= 0,
        more light out than in (M00 + |(M01, M02, M03)| > 1 + mueller_tolerance), or unpolarized light
        polarized beyond 1 + mueller_tolerance."""
    @property
    def mueller(self) -> Float64Array:
        """M0 (a read-only copy; assign a new (4, 4) array to change it: checked as in __init__)."""
    @mueller.setter
    def mueller(self, value: ArrayLike, /) -> None: ...
    @property
    def placement(self) -> str:
        """'aperture' (skyward of the optics) or 'detector' (between the optics and the detector)."""
    @placement.setter
    def placement(self, value: str, /) -> None: ...
    @property
    def gamma(self) -> float:
        """The detector's polarization angle in the focal-plane frame, radians."""
    @gamma.setter
    def gamma(self, value: float, /) -> None: ...
    @property
    def is_ideal(self) -> bool:
        """Whether M0 is exactly diag(1, 1, -1, -1)."""
    def mueller_at(self, hwp_angle: float) -> Float64Array:
        """The plate's Mueller matrix in the detector's frame at plate angle hwp_angle."""
    def __eq__(self, other: object) -> bool: ...
    def __copy__(self) -> HalfWavePlate: ...
    def __deepcopy__(self, memo: object) -> HalfWavePlate: ...

def ideal_hwp_mueller() -> Float64Array:
    """diag(1, 1, -1, -1), a read-only (4, 4) array."""

def rotated_mueller(m0: ArrayLike, angle: float) -> Float64Array:
    """R(-angle) m0 R(angle): a Mueller element turned by `angle` (radians) from the detector's axis."""

class PlateBeams:
    """A beam that turns with a half-wave plate: the engine's beams at plate angles gamma + k period / N,
    interpolated trigonometrically in each sample's hwp_angle (docs/changing.md). The plate is in the beams."""

    def __init__(self, beams: Sequence[int], period: float = ..., gamma: float = 0.0, omega: float = 0.0) -> None: ...
    @property
    def beams(self) -> list[int]: ...
    @beams.setter
    def beams(self, value: Sequence[int], /) -> None: ...
    period: float
    gamma: float
    omega: float
    """The solid angle (sr) their TOD is normalized by; 0: their mean Omega~."""

class Detector:
    """A detector: name, zeta, epsilon, gain, beam index, offset quaternion (x, y, z, w) and plate."""

    name: str
    zeta: float
    epsilon: float
    gain: float
    beam: int
    """The index of the detector's beam in the engine's beams; a negative one raises ValueError."""
    def __init__(
        self,
        name: str,
        zeta: float = 0.0,
        epsilon: float = 0.0,
        gain: float = 1.0,
        beam: int = 0,
        offset: ArrayLike | None = None,
        hwp: HalfWavePlate | None = None,
        beam_sequence: Sequence[tuple[float, int]] | None = None,
        plate_beams: PlateBeams | None = None,
    ) -> None: ...
    @property
    def offset(self) -> Float64Array:
        """The rotation from the boresight's antenna basis to the detector's, (x, y, z, w): a unit
        quaternion to within unit_quat_tolerance (else ValueError naming `offset` and the norm)."""
    @offset.setter
    def offset(self, value: ArrayLike, /) -> None: ...
    @property
    def hwp(self) -> HalfWavePlate | None:
        """The detector's half-wave plate (a copy), or None."""
    @hwp.setter
    def hwp(self, value: HalfWavePlate | None, /) -> None: ...
    @property
    def beam_sequence(self) -> list[tuple[float, int]]:
        """A beam that changes with time: [(time, beam), ...], seconds strictly ascending, two nodes or more,
        linearly interpolated between them (docs/beams.md); empty: the fixed beam `beam`."""
    @beam_sequence.setter
    def beam_sequence(self, value: Sequence[tuple[float, int]] | None, /) -> None: ...
    @property
    def plate_beams(self) -> PlateBeams | None:
        """A beam that turns with a half-wave plate (a copy), or None."""
    @plate_beams.setter
    def plate_beams(self, value: PlateBeams | None, /) -> None: ...
    def set_offset(self, xi: float, eta: float, gamma: float) -> None: ...
    def offset_xi_eta_gamma(self) -> tuple[float, float, float]: ...

class FocalPlane:
    """The detectors of an engine, in order."""

    def __init__(self) -> None: ...
    def add(
        self,
        detector: Detector | str,
        zeta: float = 0.0,
        epsilon: float = 0.0,
        gain: float = 1.0,
        beam: int = 0,
        offset: ArrayLike | None = None,
        hwp: HalfWavePlate | None = None,
        beam_sequence: Sequence[tuple[float, int]] | None = None,
        plate_beams: PlateBeams | None = None,
    ) -> int: ...
    def add_pair(
        self,
        name: str,
        zeta: float = 0.0,
        beam_a: int = 0,
        beam_b: int = 0,
        epsilon: float = 0.0,
        gain_a: float = 1.0,
        gain_b: float = 1.0,
        hwp: HalfWavePlate | None = None,
    ) -> int:
        """A PSB pair; hwp: a plate in front of both, its gamma a's (b's is gamma - 90 deg)."""
    def __len__(self) -> int: ...
    def __getitem__(self, key: int | str, /) -> Detector: ...
    @property
    def detectors(self) -> list[Detector]: ...
    @property
    def names(self) -> list[str]: ...
    @staticmethod
    def read_toast(path: str | os.PathLike[str], beam: int = 0, hwp: HalfWavePlate | None = None) -> FocalPlane:
        """A TOAST 3 focal-plane file; hwp: a plate for every detector, gamma from the file's column."""
    @staticmethod
    def from_columns(
        columns: Mapping[str, Any] | Any,
        beam: int | Mapping[str, int] | Sequence[int] | None = None,
        hwp: HalfWavePlate | None = None,
    ) -> FocalPlane:
        """From a dict of columns or an astropy table (pisco.focal_plane_from_columns)."""
    @staticmethod
    def from_toast(
        focalplane: Any,
        beam: int | Mapping[str, int] | Sequence[int] | None = None,
        detectors: Sequence[str] | None = None,
        hwp: HalfWavePlate | None = None,
    ) -> FocalPlane:
        """From a TOAST 3 Focalplane, its table or its HDF5 file (pisco.focal_plane_from_toast)."""

def default_hwp_gamma(detector: Detector) -> float:
    """The gamma of a detector's half-wave plate when its table gives none: its offset's gamma plus zeta."""

def read_toast_focal_plane(path: str | os.PathLike[str], beam: int = 0) -> tuple[FocalPlane, Float64Array, float]:
    """(FocalPlane, fwhm per detector in radians, sample rate in Hz) of a TOAST 3 focal-plane file."""

class DeconvolvingMapmaker:
    """The beam-deconvolving map-maker: conjugate gradients on (A^T A + lambda) s = A^T d."""

    def __init__(
        self,
        engine: Engine,
        max_iterations: int = 100,
        tolerance: float = 1e-6,
        regularization: float = 0.0,
        target_fwhm: float = 0.0,
        regularize: Literal["all", "polarization"] = "all",
        rcond_min: float = 1e-3,
        coverage_nside: int = 0,
    ) -> None: ...
    def add(
        self,
        detector: int | str,
        tod: Float64Array,
        theta: Float64Array | None = None,
        phi: Float64Array | None = None,
        psi: Float64Array | None = None,
        *,
        boresight_quats: Float64Array | None = None,
        hwp_angle: Float64Array | None = None,
    ) -> None:
        """Adds a chunk's TOD to the right-hand side A^T d."""
    def solve(
        self,
        survey: Callable[[], Iterable[dict[str, Any]]],
        progress: Callable[[int, float, float], None] | None = None,
    ) -> dict[str, Any]:
        """Solves, replaying survey() once an iteration; returns the maps and the convergence."""

class SourceTrack:
    """A point source's track (docs/sources.md): its direction and flux at strictly increasing times;
    between two, the great circle at a constant rate and the flux linear in time; one point: fixed.
    Flux: the integral of the source's Stokes brightness, the sky's units times steradians (COSMO)."""

    name: str
    time: list[float]
    theta: list[float]
    phi: list[float]
    I: list[float]
    Q: list[float]
    U: list[float]
    V: list[float]

    def __init__(
        self,
        name: str,
        time: Sequence[float],
        theta: Sequence[float],
        phi: Sequence[float],
        I: Sequence[float],
        Q: Sequence[float] = ...,
        U: Sequence[float] = ...,
        V: Sequence[float] = ...,
    ) -> None:
        """One value per time (Q, U, V may be left out: zero); pisco.Error names a bad point."""
    @staticmethod
    def fixed(name: str, theta: float, phi: float, I: float, Q: float = 0.0, U: float = 0.0, V: float = 0.0) -> SourceTrack:
        """A source fixed at (theta, phi)."""
    @staticmethod
    def read_csv(path: str | os.PathLike[str], name: str) -> SourceTrack:
        """The track in a CSV track file (columns time_s, theta_deg, phi_deg, I and optionally Q, U, V)."""
    def write_csv(self, path: str | os.PathLike[str]) -> None:
        """Writes the track as a CSV track file, whole or not at all."""

class Engine:
    """The convolution engine: set up once for a sky, beams and focal plane; then pointing -> TOD."""

    def __init__(
        self,
        sky: Sky,
        beams: Beamsor | Sequence[Beamsor],
        focal_plane: FocalPlane,
        backend: str = "auto",
        device: str = "auto",
        chunk_samples: int = 0,
        normalization: str = "integral",
        threads: int = 0,
        arithmetic: str = "auto",
        unseen: UnseenPolicy = "error",
        quadrature: Literal["corrected", "plain"] = "corrected",
    ) -> None: ...
    def add_sources(
        self,
        detector: int | str,
        time: Float64Array,
        sources: Sequence[SourceTrack],
        theta: Float64Array | None = None,
        phi: Float64Array | None = None,
        psi: Float64Array | None = None,
        *,
        boresight_quats: Float64Array | None = None,
        out: Float64Array | None = None,
        hwp_angle: Float64Array | None = None,
    ) -> Float64Array:
        """Point sources added into a detector's TOD: its beam at each source's direction per sample, exactly
        (docs/sources.md); time on the sources' clock; out None: new zeros. Needs normalization='integral'."""
    def convolve(
        self,
        detector: int | str,
        theta: Float64Array | None = None,
        phi: Float64Array | None = None,
        psi: Float64Array | None = None,
        *,
        boresight_quats: Float64Array | None = None,
        out: Float64Array | None = None,
        accumulate: bool = False,
        hwp_angle: Float64Array | None = None,
        time: Float64Array | None = None,
    ) -> Float64Array:
        """The TOD of one detector for a chunk of boresight pointing (angles or quaternions).

        hwp_angle: the plate's angle per sample (1-D float64, radians, focal-plane frame), required
        for a detector with a plate and refused for one without. time: each sample's time (seconds),
        required for a detector whose beam changes with time (Detector.beam_sequence), ignored otherwise.
        """
    def adjoint(
        self,
        detector: int | str,
        tod: Float64Array,
        theta: Float64Array | None = None,
        phi: Float64Array | None = None,
        psi: Float64Array | None = None,
        *,
        boresight_quats: Float64Array | None = None,
        out: Float64Array | None = None,
        hwp_angle: Float64Array | None = None,
        time: Float64Array | None = None,
    ) -> Float64Array:
        """The adjoint of convolve(): A^T tod added into out ((4, npix): I, Q, U, V) or new zeros.

        sum(sky * A^T d) == sum(A sky * d) to rounding; backends without it raise UnavailableError.
        """
    def adjoint_diagonal(
        self,
        detector: int | str,
        theta: Float64Array | None = None,
        phi: Float64Array | None = None,
        psi: Float64Array | None = None,
        *,
        boresight_quats: Float64Array | None = None,
        out: Float64Array | None = None,
        hwp_angle: Float64Array | None = None,
        time: Float64Array | None = None,
    ) -> Float64Array:
        """The diagonal of A^T A for these samples, added into out ((4, npix)) or new zeros."""
    def normal(
        self,
        detector: int | str,
        theta: Float64Array | None = None,
        phi: Float64Array | None = None,
        psi: Float64Array | None = None,
        *,
        boresight_quats: Float64Array | None = None,
        out: Float64Array | None = None,
        hwp_angle: Float64Array | None = None,
        time: Float64Array | None = None,
    ) -> Float64Array:
        """A^T A sky for these samples (adjoint of convolve of the engine's sky), added into out ((4, npix)) or new zeros.

        One pass over each disc where the backend can (simd); the same result as convolve() then adjoint().
        """
    def set_sky(self, sky: Sky) -> None:
        """Replaces the sky (the same NSIDE), keeping beams, detectors and options."""
    def prepare(self) -> None:
        """Completes the set-up that runs in the background (the sky's polar copy); optional."""
    @property
    def npix(self) -> int: ...
    def convolve_detectors(
        self,
        detectors: Sequence[int | str],
        theta: Float64Array | None = None,
        phi: Float64Array | None = None,
        psi: Float64Array | None = None,
        *,
        boresight_quats: Float64Array | None = None,
        out: Sequence[Float64Array] | Float64Array | None = None,
        accumulate: bool = False,
        hwp_angle: Float64Array | None = None,
        time: Float64Array | None = None,
    ) -> list[Float64Array]:
        """convolve() for several detectors on the same boresight pointing, checked once and staged by a
        GPU backend once in each of its two slots rather than once per detector: a list of their TODs,
        the bits convolve() gives.
        `out`: one array a detector (a list, or a 2-D array's rows), written or, with accumulate, added
        to. hwp_angle goes to the detectors with a plate, time to those whose beam changes with time."""
    def submit(
        self,
        detector: int | str,
        theta: Float64Array | None = None,
        phi: Float64Array | None = None,
        psi: Float64Array | None = None,
        *,
        boresight_quats: Float64Array | None = None,
        out: Float64Array | None = None,
        accumulate: bool = False,
        hwp_angle: Float64Array | None = None,
        time: Float64Array | None = None,
    ) -> int:
        """convolve(), asynchronously; `out` (required) is written by the time wait(ticket) returns."""
    def flag_samples(
        self,
        detector: int | str,
        theta: Float64Array | None = None,
        phi: Float64Array | None = None,
        psi: Float64Array | None = None,
        *,
        boresight_quats: Float64Array | None = None,
    ) -> NDArray[numpy.bool_]:
        """Masked skies (unseen='flag'): True where the sample's disc holds an UNSEEN sky pixel."""
    def wait(self, ticket: int | None = None) -> None: ...
    def close(self) -> None: ...
    @property
    def closed(self) -> bool: ...
    @property
    def backend(self) -> str: ...
    @property
    def device(self) -> str: ...
    @property
    def polar_samples(self) -> int:
        """Samples summed so far on the sky's polar copy (quadrature='corrected')."""

    @property
    def staged_samples(self) -> int:
        """Pointing samples staged for the device so far (vulkan, cuda): once a detector, or once a
        slot for convolve_detectors; 0 on cpu and simd."""
    @property
    def mean_disc_pixels(self) -> float: ...
    @property
    def sidelobe_nside(self) -> int: ...
    @property
    def unseen_pixels(self) -> int:
        """The number of UNSEEN sky pixels taken as 0 (unseen='zero' or 'flag')."""
    @property
    def focal_plane(self) -> FocalPlane: ...
    def __len__(self) -> int: ...
    def __enter__(self) -> Engine: ...
    def __exit__(self, exc_type: object = None, exc_value: object = None, traceback: object = None) -> None: ...

class Simulation:
    """A whole simulation from a simulation file (docs/config.md), as `pisco-vk run` runs it (no plots)."""

    def __init__(
        self,
        path: str | os.PathLike[str],
        output_dir: str | os.PathLike[str] | None = None,
        backend: str | None = None,
        device: str | None = None,
        data_dir: str | os.PathLike[str] | None = None,
    ) -> None: ...
    @staticmethod
    def from_file(
        path: str | os.PathLike[str],
        output_dir: str | os.PathLike[str] | None = None,
        backend: str | None = None,
        device: str | None = None,
        data_dir: str | os.PathLike[str] | None = None,
    ) -> Simulation:
        """Reads a simulation file; raises pisco.Error naming the file and key."""
    @property
    def source(self) -> str: ...
    @property
    def output_dir(self) -> str: ...
    @output_dir.setter
    def output_dir(self, value: str | os.PathLike[str]) -> None: ...
    @property
    def backend(self) -> str: ...
    @backend.setter
    def backend(self, value: str) -> None: ...
    @property
    def detectors(self) -> list[str]: ...
    def run(self) -> dict[str, Any]:
        """Runs it (the GIL released): the TOD file, maps and spectra in the output directory. The dict:
        files, tod, samples, detectors, samples_per_detector, mean_disc_pixels, convolution_seconds,
        seconds, backend, device, flagged, solved_pixels, nothing_solved, log; with [mapmaker] type =
        "deconvolve", also deconvolution_iterations and deconvolution_residual."""
