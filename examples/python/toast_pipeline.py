#!/usr/bin/env python3
"""A TOAST 3 pipeline with PISCO-VK's beam convolution: satellite scan -> PixelConvolve -> binned map.

A 7-pixel hexagonal focal plane (14 detectors, 1 deg FWHM) scans a synthesized polarized sky from a
spinning, precessing satellite; pisco.toast.PixelConvolve writes each detector's beam-convolved TOD
into the observation's `signal`; TOAST's own binned map-maker makes I, Q, U maps, compared with the
input sky smoothed by the beam, and drawn into a PNG.

Needs: the pisco package (README.md, "Python": pip install . into a virtual environment), toast, healpy, matplotlib.
Run:   python examples/python/toast_pipeline.py [--hours 4] [--backend auto] [--out pisco-toast-example]
"""

import argparse
import os
import time
from datetime import datetime, timezone

os.environ.setdefault("TOAST_LOGLEVEL", "WARNING")

import healpy as hp  # noqa: E402
import numpy as np  # noqa: E402
from astropy import units as u  # noqa: E402

import toast  # noqa: E402
import toast.ops  # noqa: E402
from toast.instrument import SpaceSite, Telescope  # noqa: E402
from toast.instrument_sim import fake_hexagon_focalplane  # noqa: E402
from toast.schedule_sim_satellite import create_satellite_schedule  # noqa: E402

import pisco  # noqa: E402
import pisco.toast  # noqa: E402


def synthesize_sky(nside, lmax, fwhm, seed):
    """A CMB-like polarized sky (C_l ~ 1/l^2 in uK^2, E at 1/10 and B at 1/100 of T), smoothed."""
    ell = np.arange(lmax + 1)
    cl = np.zeros((4, lmax + 1))
    cl[0, 2:] = 2 * np.pi * 1000.0 / (ell[2:] * (ell[2:] + 1.0))
    cl[1], cl[2] = cl[0] / 10, cl[0] / 100
    np.random.seed(seed)
    alm = hp.synalm(cl, lmax=lmax, new=True)
    return hp.smoothalm(alm, fwhm=fwhm, pol=True, inplace=False)


def main():
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--hours", type=float, default=4.0, help="observation length (default 4)")
    p.add_argument("--backend", default="auto", help="pisco backend: auto, cpu, simd, vulkan, cuda")
    p.add_argument("--nside-sky", type=int, default=256)
    p.add_argument("--nside-map", type=int, default=64)
    p.add_argument("--out", default="pisco-toast-example", help="output folder")
    args = p.parse_args()
    os.makedirs(args.out, exist_ok=True)
    fwhm = np.radians(1.0)
    t0 = time.perf_counter()

    # The instrument and the scan, TOAST's own simulation operators.
    focalplane = fake_hexagon_focalplane(n_pix=7, width=5 * u.deg, sample_rate=10 * u.Hz, epsilon=0.01,
                                         fwhm=fwhm * u.rad)
    telescope = Telescope("satellite", focalplane=focalplane, site=SpaceSite("L2"))
    schedule = create_satellite_schedule(
        prefix="obs_", mission_start=datetime(2023, 1, 1, tzinfo=timezone.utc),
        observation_time=args.hours * u.hour, gap_time=0 * u.s, num_observations=1,
        prec_period=120 * u.min, spin_period=0.5 * u.min)
    data = toast.Data(toast.mpi.Comm())
    toast.ops.SimSatellite(name="sim_satellite", telescope=telescope, schedule=schedule, hwp_angle=None,
                           spin_angle=40 * u.deg, prec_angle=50 * u.deg, detset_key="pixel").apply(data)

    # The sky, in the observation's coordinates (equatorial: boresight_radec), uK.
    lmax = 2 * args.nside_sky
    alm = synthesize_sky(args.nside_sky, lmax, np.radians(1.5), seed=2023)
    sky = pisco.Sky.from_maps(hp.alm2map(alm, args.nside_sky, lmax=lmax, pol=True), units="uK_CMB")

    # The beam-convolved TOD: Gaussian beams of the focal plane's fwhm column.
    t1 = time.perf_counter()
    convolve = pisco.toast.PixelConvolve(name="pisco", sky=sky, det_data="signal", det_data_units=u.uK,
                                         backend=args.backend)
    convolve.apply(data)
    t2 = time.perf_counter()
    ob = data.obs[0]
    samples = ob.n_local_samples * len(ob.local_detectors)
    print(f"PixelConvolve ({args.backend}): {len(ob.local_detectors)} detectors x {ob.n_local_samples} samples "
          f"in {t2 - t1:.1f} s ({samples / (t2 - t1):.3g} samples/s)")

    # TOAST's binned map-maker.
    detpointing = toast.ops.PointingDetectorSimple()
    pixels = toast.ops.PixelsHealpix(nside=args.nside_map, nest=False, detector_pointing=detpointing)
    weights = toast.ops.StokesWeights(mode="IQU", detector_pointing=detpointing, hwp_angle=None)
    toast.ops.DefaultNoiseModel().apply(data)
    toast.ops.CovarianceAndHits(pixel_dist="pixel_dist", pixel_pointing=pixels, stokes_weights=weights,
                                noise_model="noise_model", rcond_threshold=1e-2, det_data_units=u.uK).apply(data)
    binner = toast.ops.BinMap(pixel_dist="pixel_dist", covariance="covariance", det_data="signal",
                              det_data_units=u.uK, pixel_pointing=pixels, stokes_weights=weights,
                              noise_model="noise_model")
    binner.apply(data)
    map_file = os.path.join(args.out, "binned_map.fits")
    data[binner.binned].write(map_file)
    hits_file = os.path.join(args.out, "hits.fits")
    data["hits"].write(hits_file)
    maps = np.array(hp.read_map(map_file, field=None, nest=False))
    hits = hp.read_map(hits_file, nest=False)
    smoothed = hp.alm2map(hp.smoothalm(alm, fwhm=fwhm, pol=True, inplace=False), args.nside_map, lmax=lmax, pol=True)
    # Pixels solved (the others are 0) and crossed often enough to have several detector angles.
    seen = (maps[0] != 0) & (maps[0] != hp.UNSEEN) & (hits >= 30)
    residual = [np.std(maps[k][seen] - smoothed[k][seen]) / np.std(smoothed[k][seen]) for k in range(3)]
    print(f"binned map: {seen.sum()} of {len(seen)} pixels at NSIDE {args.nside_map}; RMS of (map - smoothed "
          f"input) / RMS of the input: I {residual[0]:.3f}, Q {residual[1]:.3f}, U {residual[2]:.3f}")

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig = plt.figure(figsize=(15, 4))
    for k, stokes in enumerate("IQU"):
        shown = np.where(seen, maps[k], hp.UNSEEN)
        hp.mollview(shown, fig=fig.number, sub=(1, 3, k + 1), title=f"{stokes} (uK), TOAST BinMap of PixelConvolve",
                    unit="uK")
    png = os.path.join(args.out, "binned_map.png")
    fig.savefig(png, dpi=80)
    print(f"wrote {png} and {map_file}; {time.perf_counter() - t0:.1f} s in all")


if __name__ == "__main__":
    main()
