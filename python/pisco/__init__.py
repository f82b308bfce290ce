"""PISCO-VK: pixel-space beam convolution of polarized CMB skies (docs/python.md).

The C++ library through nanobind: :class:`Sky`, :class:`Beamsor`, :class:`FocalPlane`
(its :class:`Detector` objects, each with an optional :class:`HalfWavePlate`), :class:`Engine`
and :func:`devices`. Arrays pass in and out without copies (float64,
C-contiguous); the engine releases the GIL while it runs. Adapters for the simulation
frameworks live in :mod:`pisco.toast` (a TOAST 3 operator) and :mod:`pisco.litebird`
(litebird_sim's ``add_convolved_sky_to_observations``); each imports its framework only
when it is imported itself.

Angles are radians throughout (``pisco.deg`` is one degree); polarization follows the
HEALPix COSMO convention; maps are in RING ordering.
"""

from ._pisco import (
    BackendInfo,
    Beamsor,
    DeconvolvingMapmaker,
    Detector,
    DeviceError,
    Engine,
    Error,
    FileError,
    FocalPlane,
    HalfWavePlate,
    InputError,
    InternalError,
    PlateBeams,
    Simulation,
    Sky,
    SourceTrack,
    UnavailableError,
    __version__,
    ang2pix,
    default_hwp_gamma,
    deg,
    devices,
    ground_sky,
    ideal_hwp_mueller,
    mueller_tolerance,
    offset_quat,
    quat_from_pointing,
    quat_to_pointing,
    read_toast_focal_plane,
    rayleigh_jeans_in,
    rotated_mueller,
    unit_quat_tolerance,
    unseen,
    valid_nside,
)
from ._ground import horizon_pointing
from ._focal_plane import focal_plane_from_columns, focal_plane_from_toast, quat_multiply

# The table builders are FocalPlane's own constructors as well: FocalPlane.from_columns(...).
FocalPlane.from_columns = staticmethod(focal_plane_from_columns)
FocalPlane.from_toast = staticmethod(focal_plane_from_toast)

__all__ = [
    "BackendInfo",
    "Beamsor",
    "DeconvolvingMapmaker",
    "Detector",
    "DeviceError",
    "Engine",
    "Error",
    "FileError",
    "FocalPlane",
    "HalfWavePlate",
    "InputError",
    "InternalError",
    "PlateBeams",
    "Simulation",
    "Sky",
    "SourceTrack",
    "UnavailableError",
    "__version__",
    "ang2pix",
    "default_hwp_gamma",
    "deg",
    "devices",
    "focal_plane_from_columns",
    "focal_plane_from_toast",
    "ground_sky",
    "horizon_pointing",
    "ideal_hwp_mueller",
    "mueller_tolerance",
    "offset_quat",
    "quat_from_pointing",
    "quat_multiply",
    "quat_to_pointing",
    "rayleigh_jeans_in",
    "read_toast_focal_plane",
    "rotated_mueller",
    "unit_quat_tolerance",
    "unseen",
    "valid_nside",
]
