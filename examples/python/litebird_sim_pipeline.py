#!/usr/bin/env python3
"""A litebird_sim simulation with PISCO-VK's beam convolution: scan -> convolved TOD -> binned map.

Four detectors (two orthogonal pairs side by side, 1 deg FWHM) on a LiteBIRD-like spinning and precessing scan
(a spin of 20 s and a precession of 2 h, faster than LiteBIRD's, so that a few hours cover much
of the sky);
pisco.litebird.add_convolved_sky_to_observations adds the beam-convolved sky into each observation's
`tod`, as litebird_sim's own function of that name does with its 4 pi convolution; litebird_sim's
binned map-maker makes I, Q, U maps, compared with the input sky smoothed by the beam, and drawn
into a PNG.

Needs: the pisco package (README.md, "Python": pip install . into a virtual environment), litebird_sim, healpy, matplotlib.
Run:   python examples/python/litebird_sim_pipeline.py [--hours 4] [--backend auto] [--out pisco-litebird-example]
"""

import argparse
import os
import time

import healpy as hp
import numpy as np

import litebird_sim as lbs
import pisco
import pisco.litebird


def main():
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--hours", type=float, default=4.0, help="observation length (default 4)")
    p.add_argument("--backend", default="auto", help="pisco backend: auto, cpu, simd, vulkan, cuda")
    p.add_argument("--nside-sky", type=int, default=256)
    p.add_argument("--nside-map", type=int, default=64)
    p.add_argument("--out", default="pisco-litebird-example", help="output folder")
    args = p.parse_args()
    os.makedirs(args.out, exist_ok=True)
    t0 = time.perf_counter()
    fwhm_arcmin = 60.0

    # The simulation: a spinning, precessing scan (ecliptic boresight), 19 Hz detectors.
    sim = lbs.Simulation(start_time=0.0, duration_s=args.hours * 3600.0, random_seed=12345,
                         base_path=os.path.join(args.out, "litebird_sim"),
                         imo=lbs.Imo(flatfile_location=lbs.PTEP_IMO_LOCATION))
    sim.set_scanning_strategy(lbs.SpinningScanningStrategy(spin_sun_angle_rad=np.radians(45.0),
                                                           precession_rate_hz=1.0 / 7200.0,
                                                           spin_rate_hz=1.0 / 20.0),
                              delta_time_s=1.0)
    sim.set_instrument(lbs.InstrumentInfo(name="telescope", spin_boresight_angle_rad=np.radians(50.0)))
    detectors = []
    for k, angle in enumerate([0.0, 90.0, 45.0, 135.0]):
        # Two pairs side by side, 0.2 deg apart (pisco.offset_quat: a detector's offset as a quaternion).
        quat = lbs.RotQuaternion(quats=np.array(pisco.offset_quat(np.radians(0.1 if k < 2 else -0.1), 0.0, 0.0)))
        detectors.append(lbs.DetectorInfo(name=f"det{k}", channel="demo", sampling_rate_hz=19.0,
                                          fwhm_arcmin=fwhm_arcmin, pol_angle_rad=np.radians(angle), quat=quat,
                                          net_ukrts=50.0))
    (obs,) = sim.create_observations(detectors=detectors)
    sim.prepare_pointings()

    # The sky in galactic coordinates, as litebird_sim's maps are: a HealpixMap.
    lmax = 2 * args.nside_sky
    ell = np.arange(lmax + 1)
    cl = np.zeros((4, lmax + 1))
    cl[0, 2:] = 2 * np.pi * 1e-9 / (ell[2:] * (ell[2:] + 1.0))  # K^2
    cl[1], cl[2] = cl[0] / 10, cl[0] / 100
    np.random.seed(2)
    alm = hp.smoothalm(hp.synalm(cl, lmax=lmax, new=True), fwhm=np.radians(1.5), pol=True, inplace=False)
    sky = lbs.HealpixMap(values=hp.alm2map(alm, args.nside_sky, lmax=lmax, pol=True), nside=args.nside_sky,
                         units=lbs.Units.K_CMB, coordinates=lbs.CoordinateSystem.Galactic)

    # The beam-convolved TOD: Gaussian beams of the detectors' fwhm_arcmin (or pass beams=...).
    t1 = time.perf_counter()
    pisco.litebird.add_convolved_sky_to_observations(obs, sky, backend=args.backend)
    t2 = time.perf_counter()
    samples = obs.tod.size
    print(f"pisco.litebird ({args.backend}): {obs.tod.shape[0]} detectors x {obs.tod.shape[1]} samples in "
          f"{t2 - t1:.1f} s ({samples / (t2 - t1):.3g} samples/s)")

    # litebird_sim's binned map-maker, in galactic coordinates.
    result = lbs.make_binned_map(nside=args.nside_map, observations=[obs],
                                 output_coordinate_system=lbs.CoordinateSystem.Galactic)
    maps = np.asarray(getattr(result.binned_map, "values", result.binned_map))
    smoothed = hp.alm2map(hp.smoothalm(alm, fwhm=np.radians(fwhm_arcmin / 60), pol=True, inplace=False),
                          args.nside_map, lmax=lmax, pol=True)
    # Pixels seen at enough polarization angles: the 3x3 normal matrix well conditioned.
    invnpp = np.asarray(result.invnpp)
    seen = np.all(np.isfinite(maps), axis=0) & (maps[0] != hp.UNSEEN) & np.all(np.isfinite(invnpp), axis=(1, 2))
    seen[seen] &= np.linalg.cond(invnpp[seen]) < 100
    residual = [np.std(maps[k][seen] - smoothed[k][seen]) / np.std(smoothed[k][seen]) for k in range(3)]
    print(f"binned map: {seen.sum()} of {len(seen)} pixels at NSIDE {args.nside_map}; RMS of (map - smoothed "
          f"input) / RMS of the input: I {residual[0]:.3f}, Q {residual[1]:.3f}, U {residual[2]:.3f}")
    map_file = os.path.join(args.out, "binned_map.fits")
    hp.write_map(map_file, np.where(seen, maps, hp.UNSEEN), overwrite=True, column_units="K_CMB", coord="G")

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig = plt.figure(figsize=(15, 4))
    for k, stokes in enumerate("IQU"):
        hp.mollview(np.where(seen, maps[k] * 1e6, hp.UNSEEN), fig=fig.number, sub=(1, 3, k + 1), unit="uK",
                    title=f"{stokes}, litebird_sim binned map of pisco.litebird")
    png = os.path.join(args.out, "binned_map.png")
    fig.savefig(png, dpi=80)
    print(f"wrote {png} and {map_file}; {time.perf_counter() - t0:.1f} s in all")


if __name__ == "__main__":
    main()
