#!/usr/bin/env python3
"""A planet's track file for a simulation's [[sources]] file (docs/sources.md, "Planets"; docs/formats.md,
"Source tracks"): pisco.planets.planet_track at times 0, step, 2 step, ... up to the duration (and the
duration itself), written with SourceTrack.write_csv. For a ces scan give its site and start: the times
are seconds from that start, the directions in the scan's frame.

Run with the Python package built in build/ (astropy from the tests' environment):
    PYTHONPATH=build/python build/python-venv/bin/python tools/planet_track.py jupiter \\
        --start 2026-11-28T07:30:00Z --duration-s 960 --step-s 30 --site -22.96 -67.79 5200 \\
        --brightness-temperature 170 --frequency 150 --units uK_CMB -o assets/examples/jupiter_track.csv
"""

import argparse
import math
import sys

import numpy as np

import pisco
from pisco import planets


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("body", help=f"one of {', '.join(planets.BODIES)}")
    ap.add_argument("--start", required=True, help="UTC start, as the ces scan's start ('2026-11-28T07:30:00Z')")
    ap.add_argument("--duration-s", type=float, required=True, help="seconds the track covers from the start")
    ap.add_argument("--step-s", type=float, default=60.0, help="seconds between the track's points (60)")
    ap.add_argument("--site", type=float, nargs="+", metavar="LAT_DEG LON_DEG [HEIGHT_M]",
                    help="the ground site (latitude, east longitude, height)")
    ap.add_argument("--orbit", choices=["l2"], help="a spacecraft at L2 instead of a site")
    ap.add_argument("--frame", default=None, choices=["ces", "equatorial", "ecliptic", "galactic"],
                    help="default: ces with a site, else ecliptic")
    ap.add_argument("--brightness-temperature", type=float, help="K (Rayleigh-Jeans)")
    ap.add_argument("--frequency", type=float, help="GHz (for K_CMB)")
    ap.add_argument("--units", default="K_CMB", choices=["K_CMB", "uK_CMB", "K_RJ", "uK_RJ"],
                    help="the sky's units (pisco-vk's synthesized skies: uK_CMB)")
    ap.add_argument("--flux", type=float, help="the flux in units times sr, instead of a brightness temperature")
    ap.add_argument("-o", "--output", required=True, help="the CSV track file to write")
    args = ap.parse_args()
    if not (args.duration_s > 0 and math.isfinite(args.duration_s)) or not (args.step_s > 0 and math.isfinite(args.step_s)):
        ap.error("--duration-s and --step-s must be positive")
    if args.duration_s / args.step_s > 1e7:
        ap.error("--duration-s / --step-s: more than 1e7 points; take a longer step")
    times = np.arange(0.0, args.duration_s, args.step_s)
    times = np.append(times, args.duration_s) if times[-1] < args.duration_s else times
    frame = args.frame or ("ces" if args.site else "ecliptic")
    start = args.start[:-1] if args.start.endswith("Z") else args.start
    try:
        track = planets.planet_track(args.body, start, times, site=tuple(args.site) if args.site else None,
                                     orbit=args.orbit, frame=frame, brightness_temperature=args.brightness_temperature,
                                     frequency=args.frequency, units=args.units, flux=args.flux)
        track.write_csv(args.output)
    except (ValueError, pisco.Error) as e:
        print(f"planet_track.py: {e}", file=sys.stderr)
        return 2
    print(f"{args.output}: {track.name}, {len(track.time)} points over {args.duration_s:g} s, flux I "
          f"{min(track.I):.4g} to {max(track.I):.4g} {args.units} sr, theta {math.degrees(track.theta[0]):.4f} deg, "
          f"phi {math.degrees(track.phi[0]):.4f} deg at the start ({frame})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
