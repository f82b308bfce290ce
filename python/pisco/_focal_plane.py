"""Focal planes from tables: a dict of columns, an astropy table, or a TOAST 3 focal plane.

The TOAST mapping is the one of ``pisco::read_toast_focal_plane`` (docs/formats.md, "TOAST focal
planes"): epsilon = pol_leakage (or (1 - eta) / (1 + eta) from pol_efficiency eta), gain =
2 / (1 + epsilon), zeta = psi_pol, offset = quat R_z(-zeta). The TOD is then TOAST's
I + eta (Q cos 2a + U sin 2a), a the polarization angle of TOAST's detector quaternion. With a
half-wave plate, each detector's plate has TOAST's ``gamma`` (the plate angle's origin).
"""

import os

import numpy as np

from ._pisco import Detector, FocalPlane, HalfWavePlate, default_hwp_gamma

__all__ = ["focal_plane_from_columns", "focal_plane_from_toast", "quat_multiply"]


def quat_multiply(p, q):
    """Hamilton product p q of quaternions (x, y, z, w): the rotation q, then p. Broadcasts."""
    p = np.asarray(p, dtype=np.float64)
    q = np.asarray(q, dtype=np.float64)
    px, py, pz, pw = np.moveaxis(p, -1, 0)
    qx, qy, qz, qw = np.moveaxis(q, -1, 0)
    return np.stack(
        [
            pw * qx + px * qw + py * qz - pz * qy,
            pw * qy - px * qz + py * qw + pz * qx,
            pw * qz + px * qy - py * qx + pz * qw,
            pw * qw - px * qx - py * qy - pz * qz,
        ],
        axis=-1,
    )


def _column(columns, key):
    """A column as a float64 numpy array in radians where it carries an angle unit, else as is."""
    value = columns[key]
    if hasattr(value, "unit") and value.unit is not None and hasattr(value, "to_value"):
        from astropy import units as u

        if value.unit.physical_type == "angle":
            return np.asarray(value.to_value(u.rad), dtype=np.float64)
        return np.asarray(value.to_value(), dtype=np.float64)
    return np.asarray(value)


def _has(columns, key):
    names = getattr(columns, "colnames", None)
    return key in (names if names is not None else columns)


def _beam_indices(names, beam):
    if beam is None:
        return [0] * len(names)
    if isinstance(beam, (int, np.integer)):
        return [int(beam)] * len(names)
    if isinstance(beam, dict):
        missing = [n for n in names if n not in beam]
        if missing:
            raise KeyError(f"beam: no beam index for detectors {missing}")
        return [int(beam[n]) for n in names]
    indices = [int(b) for b in beam]
    if len(indices) != len(names):
        raise ValueError(f"beam: {len(indices)} indices for {len(names)} detectors")
    return indices


def _plate_for(hwp, gamma):
    """A copy of the plate `hwp` with the detector's own gamma."""
    return HalfWavePlate(hwp.mueller, placement=hwp.placement, gamma=float(gamma))


def focal_plane_from_columns(columns, beam=None, hwp=None):
    """A FocalPlane from a table of detectors, one row each.

    ``columns``: a dict of equal-length sequences or an astropy Table. Keys: ``name`` (required);
    ``zeta`` (polarization angle), ``epsilon``, ``gain``, ``beam`` (index into the engine's beams);
    the offset as ``quat`` ((n, 4), x, y, z, w) or as ``xi``, ``eta``, ``gamma`` (pisco's
    focal-plane coordinates); ``hwp_gamma``, each detector's polarization angle in the focal-plane
    frame for its plate. Angles in radians, or astropy Quantities in any angle unit.
    ``beam`` (an index, a dict name -> index or a sequence) overrides the column.
    ``hwp``: a :class:`HalfWavePlate` in front of every detector, each with its own gamma: the
    ``hwp_gamma`` column, else the detector's polarization angle in the focal plane (its offset's
    gamma plus zeta, as ``pisco-vk run`` takes it).
    """
    if hwp is not None and not isinstance(hwp, HalfWavePlate):
        raise TypeError(f"hwp: expected a pisco.HalfWavePlate or None, got {type(hwp).__name__}")
    if not _has(columns, "name"):
        raise KeyError("columns: a 'name' column is required")
    names = [str(n) for n in columns["name"]]
    n = len(names)

    def get(key, default):
        if not _has(columns, key):
            return np.full(n, default, dtype=np.float64)
        values = np.asarray(_column(columns, key), dtype=np.float64).reshape(-1)
        if len(values) != n:
            raise ValueError(f"columns: '{key}' has {len(values)} rows, 'name' has {n}")
        return values

    zeta, epsilon, gain = get("zeta", 0.0), get("epsilon", 0.0), get("gain", 1.0)
    if beam is None and _has(columns, "beam"):
        beam = [int(b) for b in columns["beam"]]
    beams = _beam_indices(names, beam)
    quats = xi_eta_gamma = None
    if _has(columns, "quat"):
        quats = np.asarray(_column(columns, "quat"), dtype=np.float64).reshape(n, 4)
    elif _has(columns, "xi") or _has(columns, "eta") or _has(columns, "gamma"):
        xi_eta_gamma = np.stack([get("xi", 0.0), get("eta", 0.0), get("gamma", 0.0)], axis=-1)
    hwp_gamma = get("hwp_gamma", 0.0) if hwp is not None and _has(columns, "hwp_gamma") else None
    if hwp_gamma is not None and not np.all(np.isfinite(hwp_gamma)):
        raise ValueError("columns: 'hwp_gamma' must be finite")
    fp = FocalPlane()
    for i, name in enumerate(names):
        d = Detector(name, zeta=float(zeta[i]), epsilon=float(epsilon[i]), gain=float(gain[i]), beam=beams[i])
        if quats is not None:
            try:
                d.offset = quats[i]
            except ValueError as e:  # not a unit quaternion: named by its row
                raise ValueError(f"columns: 'quat' row {i} (detector {name}): {e}") from None
        elif xi_eta_gamma is not None:
            d.set_offset(*(float(v) for v in xi_eta_gamma[i]))
        if hwp is not None:
            gamma = hwp_gamma[i] if hwp_gamma is not None else default_hwp_gamma(d)
            d.hwp = _plate_for(hwp, gamma)
        fp.add(d)
    return fp


def focal_plane_from_toast(focalplane, beam=None, detectors=None, hwp=None):
    """A FocalPlane from a TOAST 3 focal plane, mapped as docs/formats.md says.

    ``focalplane``: a ``toast.instrument.Focalplane``, its ``detector_data`` table, or the path of a
    file written by ``Focalplane.save_hdf5``. ``beam``: the beam index of every detector, or a dict
    name -> index, or a sequence in the table's order. ``detectors``: the names to keep (default all),
    in that order. ``hwp``: a :class:`HalfWavePlate` in front of every detector, each with gamma from
    the table's ``gamma`` column, TOAST's own plate angle origin (without the column: the detector's
    polarization angle in the focal plane, as ``pisco-vk run`` takes it).
    """
    if isinstance(focalplane, (str, os.PathLike)):
        fp = FocalPlane.read_toast(os.fspath(focalplane), hwp=hwp)
        table = {
            "name": fp.names,
            "zeta": [d.zeta for d in fp.detectors],
            "epsilon": [d.epsilon for d in fp.detectors],
            "gain": [d.gain for d in fp.detectors],
            "quat": [d.offset for d in fp.detectors],
        }
        if hwp is not None:
            table["hwp_gamma"] = [d.hwp.gamma for d in fp.detectors]
        if detectors is not None:
            keep = [table["name"].index(n) for n in detectors]
            table = {k: [v[i] for i in keep] for k, v in table.items()}
        return focal_plane_from_columns(table, beam=beam, hwp=hwp)
    table = getattr(focalplane, "detector_data", focalplane)
    names = [str(n) for n in table["name"]]
    rows = list(range(len(names)))
    if detectors is not None:
        where = {n: i for i, n in enumerate(names)}
        missing = [n for n in detectors if n not in where]
        if missing:
            raise KeyError(f"detectors: not in the focal plane: {missing}")
        rows = [where[n] for n in detectors]
    n = len(rows)
    quat = np.asarray(table["quat"], dtype=np.float64).reshape(-1, 4)[rows]
    zeta = _column(table, "psi_pol")[rows].astype(np.float64) if _has(table, "psi_pol") else np.zeros(n)
    if _has(table, "pol_leakage"):
        epsilon = np.asarray(table["pol_leakage"], dtype=np.float64)[rows]
    elif _has(table, "pol_efficiency"):
        eta = np.asarray(table["pol_efficiency"], dtype=np.float64)[rows]
        epsilon = (1 - eta) / (1 + eta)
    else:
        epsilon = np.zeros(n)
    if np.any((epsilon < 0) | (epsilon > 1)) or not np.all(np.isfinite(epsilon)):
        raise ValueError("focal plane: pol_leakage (epsilon) must lie in [0, 1]")
    # offset = quat R_z(-zeta): the antenna basis is the beam frame, the polarization axis at zeta in it.
    rz = np.stack([np.zeros(n), np.zeros(n), np.sin(-zeta / 2), np.cos(-zeta / 2)], axis=-1)
    offset = quat_multiply(quat, rz)
    columns = {
        "name": [names[i] for i in rows],
        "zeta": zeta,
        "epsilon": epsilon,
        "gain": 2.0 / (1.0 + epsilon),
        "quat": offset,
    }
    if hwp is not None and _has(table, "gamma"):
        # TOAST's plate angle origin: the detector's polarization angle in the focal-plane frame.
        columns["hwp_gamma"] = np.asarray(_column(table, "gamma"), dtype=np.float64)[rows]
    if beam is not None and not isinstance(beam, (int, np.integer, dict)):
        beam = [list(beam)[i] for i in rows]
    return focal_plane_from_columns(columns, beam=beam, hwp=hwp)
