#!/usr/bin/env python3
"""Export TOAST 3's own detector pointing expansion for cross-checking.

This script builds a small TOAST focal plane, simulates one ground observation
and one satellite observation with TOAST's own simulation operators, expands
the detector pointing with ``toast.ops.PointingDetectorSimple`` and computes
the polarization weights with ``toast.ops.StokesWeights`` (mode ``IQU``; with
``--hwp-rpm``, through TOAST's ideal rotating half-wave plate).  Everything is
written to HDF5 so that another pointing code can be compared against TOAST
sample by sample.

It needs TOAST 3 (PyPI package ``toast``), ``h5py``, ``numpy`` and ``astropy``;
no MPI is required (``toast.mpi.Comm()`` works without ``mpi4py``) and nothing
is downloaded at run time (the ground simulation uses PyEphem for the
horizontal-to-equatorial rotation).

Outputs in ``OUTDIR``:

``focalplane.h5``
    (alone with ``--which focalplane``) The focal plane written by ``toast.instrument.Focalplane.save_hdf5`` (root
    attribute ``focalplane_class``; compound dataset ``focalplane`` with one row
    per detector, ``quat`` is a ``float64[4]`` sub-array field in TOAST layout
    (x, y, z, w); dataset ``focalplane.__table_column_meta__`` holds astropy's
    YAML header with units and the ``sample_rate`` / ``field_of_view`` meta).
    TOAST's hexagon puts every detector's ``gamma`` at a multiple of 45 deg;
    ``--gamma-step S`` turns the detectors of pixel k (both of a pair) by k S
    about their lines of sight (``gamma`` + k S, ``quat`` rebuilt from xi, eta
    and the new gamma with TOAST's ``xieta_to_quat``), so that the plate's
    4 gamma term is not a multiple of 180 deg.

``toast_ground.h5`` and ``toast_satellite.h5``
    ``times`` (N,) float64, UNIX seconds.
    ``boresight`` (N, 4) float64: the boresight quaternions (x, y, z, w) exactly
    as TOAST holds them in the observation's shared data under the key named
    by the file attribute ``boresight_key`` (``boresight_radec``: ICRS/equatorial).
    For the ground file also ``boresight_azel`` (N, 4), ``azimuth`` and
    ``elevation`` (N,) in radians.
    ``hwp_angle`` (N,) float64 (with ``--hwp-rpm``): TOAST's per-sample
    half-wave plate angle (``ob.shared["hwp_angle"]``, radians, focal-plane
    frame), as SimGround / SimSatellite make it from ``hwp_rpm``; file
    attribute ``hwp_rpm``.
    ``detectors/<name>/quats`` (N, 4): TOAST's detector quaternions,
    ``boresight (x) fp_quat`` as produced by PointingDetectorSimple.
    ``detectors/<name>/dir`` (N, 3): line of sight, ``qarray.rotate(quats, z)``.
    ``detectors/<name>/weights`` (N, 3): I, Q, U weights from StokesWeights
    (COSMO convention, TOAST default; with ``--hwp-rpm`` given ``hwp_angle``,
    i.e. through an ideal half-wave plate).
    ``detectors/<name>/fp_quat`` (4,): the detector's focal-plane quaternion
    (also stored as an attribute of the group, together with ``gamma`` and
    ``pol_leakage``).

Conventions (TOAST 3): quaternions are stored (x, y, z, w) and ``qarray.mult``
is the Hamilton product, ``rotate(mult(p, q), v) == rotate(p, rotate(q, v))``.
With ``q`` a detector quaternion, ``d = rotate(q, z)`` is the line of sight and
``o = rotate(q, x)`` the polarization-sensitive direction.  With
``theta_hat``/``phi_hat`` the ISO basis at ``d``,
``alpha = atan2(o . phi_hat, o . theta_hat)`` (from theta_hat towards phi_hat,
right-handed about the outward line of sight) and StokesWeights (compiled
kernel, no HWP, COSMO) returns ``(1, eta cos 2 alpha, eta sin 2 alpha)`` with
``eta = (1-eps)/(1+eps)``, ``eps`` = focal-plane column ``pol_leakage``.

With an ideal half-wave plate at angle ``h`` (TOAST's ``hwp_angle``) and the
detector's focal-plane column ``gamma``, TOAST's compiled kernel computes
``ang = 2 (2 (gamma - h) - alpha)`` and the weights
``(1, eta cos(ang), -eta sin(ang))`` (COSMO), which is
``(1, eta cos 2(alpha + 2 theta), eta sin 2(alpha + 2 theta))`` with
``theta = h - gamma``: PISCO-VK's ideal plate, ``M(theta) = R(-theta)
diag(1, 1, -1, -1) R(theta)`` seen by a detector at ``chi = alpha``
(docs/physics.md, "Half-wave plates").  The self-check evaluates this last
form.

Unless ``--no-check`` is given, the script verifies the exported arrays against
an independent evaluation of these formulas and exits non-zero on mismatch.

Example::

    /path/to/venv/bin/python tools/toast_pointing.py --outdir /tmp/toast_out
"""

import argparse
import os
import sys
import time
import warnings


def parse_args(argv=None):
    p = argparse.ArgumentParser(
        description="Export TOAST's pointing expansion (detector quaternions, "
        "line-of-sight vectors and IQU weights) to HDF5.",
        formatter_class=argparse.ArgumentDefaultsHelpFormatter,
    )
    p.add_argument("--outdir", required=True, help="Output directory")
    p.add_argument(
        "--which",
        choices=["ground", "satellite", "both", "focalplane"],
        default="both",
        help="Which observation(s) to simulate ('focalplane': write focalplane.h5 only)",
    )
    p.add_argument(
        "--n-pix",
        type=int,
        default=7,
        help="Hexagon pixels (1, 7, 19, ...); two orthogonal detectors per pixel",
    )
    p.add_argument(
        "--fp-width", type=float, default=5.0, help="Focal plane width [deg]"
    )
    p.add_argument(
        "--pol-leakage",
        type=float,
        default=0.0,
        help="Cross-polar leakage epsilon of every detector",
    )
    p.add_argument(
        "--sample-rate", type=float, default=10.0, help="Sample rate [Hz]"
    )
    p.add_argument(
        "--ground-seconds",
        type=float,
        default=300.0,
        help="Length of the ground observation [s]",
    )
    p.add_argument(
        "--ground-el", type=float, default=50.0, help="Ground scan elevation [deg]"
    )
    p.add_argument(
        "--ground-az",
        type=float,
        nargs=2,
        default=[40.0, 60.0],
        metavar=("AZMIN", "AZMAX"),
        help="Ground scan azimuth range [deg]",
    )
    p.add_argument(
        "--boresight-angle",
        type=float,
        default=0.0,
        help="Ground boresight rotation about the line of sight [deg]",
    )
    p.add_argument(
        "--satellite-seconds",
        type=float,
        default=300.0,
        help="Length of the satellite observation [s]",
    )
    p.add_argument(
        "--spin-period", type=float, default=1.0, help="Satellite spin period [min]"
    )
    p.add_argument(
        "--prec-period",
        type=float,
        default=10.0,
        help="Satellite precession period [min]",
    )
    p.add_argument(
        "--spin-angle",
        type=float,
        default=30.0,
        help="Satellite boresight opening angle from the spin axis [deg]",
    )
    p.add_argument(
        "--prec-angle",
        type=float,
        default=65.0,
        help="Satellite spin-axis opening angle from the precession axis [deg]",
    )
    p.add_argument(
        "--hwp-rpm",
        type=float,
        default=None,
        help="Simulate an ideal half-wave plate turning at this rate (rev/min) in both "
        "observations, export TOAST's hwp_angle and weight through it",
    )
    p.add_argument(
        "--gamma-step",
        type=float,
        default=0.0,
        help="Turn the detectors of hexagon pixel k by k times this angle [deg] about "
        "their lines of sight (gamma and quat)",
    )
    p.add_argument(
        "--no-check",
        action="store_true",
        help="Skip the consistency check of the exported arrays",
    )
    return p.parse_args(argv)


# TOAST logs at INFO level by default; keep the script quiet unless asked.
os.environ.setdefault("TOAST_LOGLEVEL", "WARNING")

import numpy as np  # noqa: E402
import h5py  # noqa: E402
from astropy import units as u  # noqa: E402

import toast  # noqa: E402
import toast.ops  # noqa: E402
from toast import qarray as qa  # noqa: E402
from toast.instrument import Focalplane, GroundSite, SpaceSite, Telescope  # noqa: E402
from toast.instrument_coords import quat_to_xieta, xieta_to_quat  # noqa: E402
from toast.instrument_sim import fake_hexagon_focalplane  # noqa: E402
from toast.schedule import GroundScan, GroundSchedule  # noqa: E402
from toast.schedule_sim_satellite import create_satellite_schedule  # noqa: E402

from datetime import datetime, timedelta, timezone  # noqa: E402

BORESIGHT_KEY = "boresight_radec"
QUATS_KEY = "quats"
WEIGHTS_KEY = "weights"
HWP_KEY = "hwp_angle"


def make_focalplane(args):
    fp = fake_hexagon_focalplane(
        n_pix=args.n_pix,
        width=args.fp_width * u.degree,
        sample_rate=args.sample_rate * u.Hz,
        epsilon=args.pol_leakage,
    )
    if args.gamma_step == 0.0:
        return fp
    # Turn pixel k's detectors by k * gamma_step about their lines of sight: gamma and the
    # quaternion move together (TOAST's own xi, eta, gamma parameterization); TOAST derives
    # pol_angle and pol_efficiency again from the new table.
    table = fp.detector_data.copy()
    for col in ("pol_angle", "pol_efficiency"):
        if col in table.colnames:
            table.remove_column(col)
    pixels = list(dict.fromkeys(str(x) for x in table["pixel"]))
    step = np.radians(args.gamma_step)
    for row in table:
        turn = pixels.index(str(row["pixel"])) * step
        xi, eta, gamma = quat_to_xieta(np.array(row["quat"], dtype=np.float64))
        row["quat"] = xieta_to_quat(xi, eta, gamma + turn)
        row["gamma"] = (u.Quantity(row["gamma"]).to_value(u.rad) + turn) * u.rad
    return Focalplane(
        detector_data=table, sample_rate=fp.sample_rate, field_of_view=fp.field_of_view
    )


def hwp_options(args):
    """SimGround / SimSatellite keywords for the plate (none without --hwp-rpm)."""
    if args.hwp_rpm is None:
        return {"hwp_angle": None}
    return {"hwp_angle": HWP_KEY, "hwp_rpm": args.hwp_rpm}


def simulate_ground(args, focalplane):
    site = GroundSite("atacama", "-22:57:30", "-67:47:10", 5200.0 * u.meter)
    tele = Telescope("ground_telescope", focalplane=focalplane, site=site)
    start = datetime(2020, 1, 1, 3, 0, 0, tzinfo=timezone.utc)
    stop = start + timedelta(seconds=args.ground_seconds)
    scan = GroundScan(
        name="ground_scan",
        start=start,
        stop=stop,
        boresight_angle=args.boresight_angle * u.degree,
        az_min=args.ground_az[0] * u.degree,
        az_max=args.ground_az[1] * u.degree,
        el=args.ground_el * u.degree,
    )
    schedule = GroundSchedule(
        scans=[scan],
        site_name=site.name,
        telescope_name=tele.name,
        site_lat=site.earthloc.lat,
        site_lon=site.earthloc.lon,
        site_alt=site.earthloc.height,
    )
    data = toast.Data(toast.mpi.Comm())
    sim = toast.ops.SimGround(
        name="sim_ground",
        telescope=tele,
        schedule=schedule,
        boresight_radec=BORESIGHT_KEY,
        detset_key="pixel",
        use_ephem=True,
        **hwp_options(args),
    )
    sim.apply(data)
    return data


def simulate_satellite(args, focalplane):
    tele = Telescope("satellite_telescope", focalplane=focalplane, site=SpaceSite("L2"))
    schedule = create_satellite_schedule(
        prefix="sat_",
        mission_start=datetime(2023, 2, 23, tzinfo=timezone.utc),
        observation_time=args.satellite_seconds * u.second,
        gap_time=0 * u.second,
        num_observations=1,
        prec_period=args.prec_period * u.minute,
        spin_period=args.spin_period * u.minute,
    )
    data = toast.Data(toast.mpi.Comm())
    sim = toast.ops.SimSatellite(
        name="sim_satellite",
        telescope=tele,
        schedule=schedule,
        boresight=BORESIGHT_KEY,
        spin_angle=args.spin_angle * u.degree,
        prec_angle=args.prec_angle * u.degree,
        detset_key="pixel",
        **hwp_options(args),
    )
    sim.apply(data)
    return data


def expand_pointing(data, hwp):
    """Run TOAST's detector pointing expansion and IQU Stokes weights (through the plate if hwp)."""
    det_pointing = toast.ops.PointingDetectorSimple(
        name="det_pointing",
        boresight=BORESIGHT_KEY,
        quats=QUATS_KEY,
        # Flagged samples would otherwise get an identity boresight; export the
        # plain expansion of every sample.
        shared_flags=None,
    )
    weights = toast.ops.StokesWeights(
        name="stokes_weights",
        detector_pointing=det_pointing,
        mode="IQU",
        weights=WEIGHTS_KEY,
        hwp_angle=HWP_KEY if hwp else None,
    )
    weights.apply(data)


def reference_weights(quats, eps, hwp_angle=None, gamma=0.0):
    """Independent evaluation of the IQU weights for detector quaternions.

    With a plate: PISCO-VK's form, an ideal plate at theta = hwp_angle - gamma before a detector
    at alpha measures Q cos 2(alpha + 2 theta) + U sin 2(alpha + 2 theta).
    """
    x, y, z, w = quats.T
    # R e_x and R e_z for a unit quaternion (x, y, z, w).
    ox = np.stack([1 - 2 * (y * y + z * z), 2 * (x * y + z * w), 2 * (x * z - y * w)], axis=1)
    dz = np.stack([2 * (x * z + y * w), 2 * (y * z - x * w), 1 - 2 * (x * x + y * y)], axis=1)
    theta = np.arccos(np.clip(dz[:, 2], -1.0, 1.0))
    phi = np.arctan2(dz[:, 1], dz[:, 0])
    th_hat = np.stack([np.cos(theta) * np.cos(phi), np.cos(theta) * np.sin(phi), -np.sin(theta)], axis=1)
    ph_hat = np.stack([-np.sin(phi), np.cos(phi), np.zeros_like(phi)], axis=1)
    alpha = np.arctan2(np.sum(ox * ph_hat, axis=1), np.sum(ox * th_hat, axis=1))
    eta = (1.0 - eps) / (1.0 + eps)
    if hwp_angle is not None:
        alpha = alpha + 2.0 * (hwp_angle - gamma)
    wts = np.stack(
        [np.ones_like(alpha), eta * np.cos(2 * alpha), eta * np.sin(2 * alpha)], axis=1
    )
    return dz, wts


def export(data, path, kind, check, hwp_rpm=None):
    """Write one observation's boresight and expanded pointing to HDF5."""
    if len(data.obs) != 1:
        raise RuntimeError(f"expected exactly one {kind} observation, got {len(data.obs)}")
    ob = data.obs[0]
    fp = ob.telescope.focalplane
    zaxis = np.array([0.0, 0.0, 1.0])
    times = np.array(ob.shared["times"].data, dtype=np.float64)
    bore = np.array(ob.shared[BORESIGHT_KEY].data, dtype=np.float64)
    n_samp = len(times)
    if bore.shape != (n_samp, 4):
        raise RuntimeError(f"unexpected boresight shape {bore.shape}")
    hwp = None
    if hwp_rpm is not None:
        hwp = np.array(ob.shared[HWP_KEY].data, dtype=np.float64)
        if hwp.shape != (n_samp,):
            raise RuntimeError(f"unexpected hwp_angle shape {hwp.shape}")
    worst = 0.0
    with h5py.File(path, "w") as f:
        f.attrs["toast_version"] = toast.__version__
        f.attrs["kind"] = kind
        f.attrs["observation"] = ob.name
        f.attrs["boresight_key"] = BORESIGHT_KEY
        f.attrs["quat_layout"] = "x,y,z,w"
        f.attrs["sample_rate_hz"] = float(fp.sample_rate.to_value(u.Hz))
        f.attrs["n_samples"] = n_samp
        f.attrs["stokes_convention"] = "COSMO"
        f.attrs["telescope"] = ob.telescope.name
        f.attrs["site"] = ob.telescope.site.name
        f.create_dataset("times", data=times)
        f.create_dataset("boresight", data=bore)
        if hwp is not None:
            f.attrs["hwp_rpm"] = float(hwp_rpm)
            f.create_dataset("hwp_angle", data=hwp)
        if kind == "ground":
            f.create_dataset(
                "boresight_azel", data=np.array(ob.shared["boresight_azel"].data)
            )
            f.create_dataset("azimuth", data=np.array(ob.shared["azimuth"].data))
            f.create_dataset("elevation", data=np.array(ob.shared["elevation"].data))
        grp = f.create_group("detectors")
        dets = list(ob.local_detectors)
        grp.attrs["names"] = np.array(dets, dtype="S")
        for det in dets:
            row = fp[det]
            fp_quat = np.array(row["quat"], dtype=np.float64)
            quats = np.array(ob.detdata[QUATS_KEY][det], dtype=np.float64)
            wts = np.array(ob.detdata[WEIGHTS_KEY][det], dtype=np.float64)
            vdir = qa.rotate(quats, zaxis).reshape((-1, 3))
            eps = float(row["pol_leakage"]) if "pol_leakage" in row.colnames else 0.0
            gamma = float(u.Quantity(row["gamma"]).to_value(u.rad))
            g = grp.create_group(det)
            g.attrs["fp_quat"] = fp_quat
            g.attrs["gamma_rad"] = gamma
            g.attrs["pol_leakage"] = eps
            g.create_dataset("fp_quat", data=fp_quat)
            g.create_dataset("quats", data=quats)
            g.create_dataset("dir", data=vdir)
            g.create_dataset("weights", data=wts)
            if check:
                # Composition: detector quaternion = boresight (x) focal-plane quat.
                ref_q = qa.mult(bore, fp_quat).reshape((-1, 4))
                worst = max(worst, float(np.max(np.abs(ref_q - quats))))
                qn = quats / np.linalg.norm(quats, axis=1)[:, None]
                ref_dir, ref_w = reference_weights(qn, eps, hwp, gamma)
                worst = max(worst, float(np.max(np.abs(ref_dir - vdir))))
                worst = max(worst, float(np.max(np.abs(ref_w - wts))))
    if check and not worst < 1e-9:
        raise RuntimeError(f"{kind}: exported pointing fails self-check (max dev {worst:.3e})")
    return n_samp, len(dets), worst


def main(argv=None):
    args = parse_args(argv)
    t0 = time.perf_counter()
    os.makedirs(args.outdir, exist_ok=True)
    warnings.simplefilter("ignore")

    focalplane = make_focalplane(args)
    fp_path = os.path.join(args.outdir, "focalplane.h5")
    with h5py.File(fp_path, "w") as f:
        focalplane.save_hdf5(f)

    kinds = {"both": ["ground", "satellite"], "focalplane": []}.get(args.which, [args.which])
    summary = []
    worst_all = 0.0
    for kind in kinds:
        # Each simulation gets its own (identical, deterministic) focal plane.
        # It is not read back from focalplane.h5: TOAST 3.0.x's
        # Focalplane._get_pol_efficiency rejects its own file when
        # pol_leakage != 0 (its consistency check inverts eta).
        fp = make_focalplane(args)
        if kind == "ground":
            data = simulate_ground(args, fp)
        else:
            data = simulate_satellite(args, fp)
        expand_pointing(data, args.hwp_rpm is not None)
        path = os.path.join(args.outdir, f"toast_{kind}.h5")
        n_samp, n_det, worst = export(data, path, kind, not args.no_check, args.hwp_rpm)
        worst_all = max(worst_all, worst)
        summary.append(f"{kind}: {n_det} dets x {n_samp} samples")
        data.clear()

    dt = time.perf_counter() - t0
    check = "" if args.no_check else f" (self-check ok, {worst_all:.1e})"
    if args.hwp_rpm is not None:
        check += f", ideal half-wave plate at {args.hwp_rpm:g} rpm"
    if summary:
        print(
            f"toast {toast.__version__}: wrote {fp_path} and "
            + ", ".join(summary)
            + f" to {args.outdir} in {dt:.1f} s{check}"
        )
    else:
        print(f"toast {toast.__version__}: wrote {fp_path} ({len(focalplane.detectors)} detectors)")
    return 0


if __name__ == "__main__":
    try:
        sys.exit(main())
    except SystemExit:
        raise
    except BaseException as exc:  # noqa: BLE001
        print(f"toast_pointing.py: error: {type(exc).__name__}: {exc}", file=sys.stderr)
        sys.exit(1)
