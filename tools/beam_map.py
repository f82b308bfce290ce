#!/usr/bin/env python3
"""Beam maps from a raster over a moving source (docs/sources.md, "Planets"), against the input beam.

For a run of a simulation file with a `[[sources]]` track (a file or a table), a ces scan and
`[output] tod_pointing = true`, each detector's TOD in tod.h5 is set against the source:

- each sample's time is i / sample_rate_hz; the source's direction and flux there come from its track
  (the great circle between the points at a constant rate, the flux linear), computed here;
- each sample's offset from the source in the detector's beam frame, (rho, sigma), from the sample's
  own theta, phi, psi (docs/physics.md, "Antenna basis");
- the sky's signal under the source is taken out sweep by sweep (each az sweep of az_throw_deg /
  az_speed_deg_s seconds): a quadratic in time fitted to the sweep's samples farther than 3 FWHM
  from the source, as beam-mapping pipelines take out the atmosphere and the CMB;
  or, with --subtract OTHER_RUN, that run's TOD (the same file without its [[sources]]) is subtracted,
  which leaves the source alone;
- what is left, within `--radius` FWHM of the source, against the input beam's own value there,
  gain/2 (1 + epsilon) F(t) B(rho, sigma) / Omega~, with the elliptical Gaussian's B written out here
  and Omega~ its integral over the cap rho <= rho_max (Gauss-Legendre in rho, trapezoid in sigma).

It prints, per detector, the samples used, the residual's RMS and worst value as fractions of the
beam's peak response, the offset of the recovered beam's centroid from the input's (arcmin) and the
ratio of their widths (second moments) along the beam's x and y; and with --plot, a PNG of the
recovered map, the input and their difference on a grid in the beam frame. Only Gaussian and
elliptical beams (the analytic ones) are compared. Exit status 0, or 2 on bad input.

Run with the Python package built in build/ (h5py and matplotlib from the tests' environment):
    build/python-venv/bin/python tools/beam_map.py assets/examples/jupiter_ces.toml pisco-jupiter-out \\
        [--plot beam_map.png] [--radius 2]
"""

import argparse
import math
import os
import sys
import tomllib

import numpy as np


class Refused(Exception):
    pass


def read_track(config, path):
    """(times, unit vectors (n, 3), I) of the first [[sources]] entry: its file or its table."""
    sources = config.get("sources")
    if not sources:
        raise Refused(f"{path}: no [[sources]] to map the beam with")
    s = sources[0]
    if "file" in s:
        import pisco

        track = pisco.SourceTrack.read_csv(os.path.join(os.path.dirname(path), s["file"]), s["name"])
        t, theta, phi, flux = (np.asarray(x, dtype=float) for x in (track.time, track.theta, track.phi, track.I))
    else:
        def values(key):
            v = s.get(key)
            return np.atleast_1d(np.asarray(v, dtype=float))

        t = values("time_s") if "time_s" in s else np.zeros(1)
        theta, phi, flux = np.radians(values("theta_deg")), np.radians(values("phi_deg")), values("I")
    if np.any(np.asarray(s.get("Q", 0.0)) != 0) or np.any(np.asarray(s.get("U", 0.0)) != 0):
        raise Refused(f"{path}: [[sources]] {s['name']}: a polarized source; the beam map takes an unpolarized one")
    k = np.stack([np.sin(theta) * np.cos(phi), np.sin(theta) * np.sin(phi), np.cos(theta)], axis=1)
    return s["name"], t, k, flux


def source_at(times, t, k, flux):
    """The source's unit vector and flux at each time: slerp between the track's points, flux linear."""
    if len(t) == 1:
        return np.repeat(k, len(times), axis=0), np.full(len(times), flux[0])
    if times.min() < t[0] or times.max() > t[-1]:
        raise Refused(f"the samples' times {times.min():g} to {times.max():g} s leave the track ({t[0]:g} to {t[-1]:g} s)")
    j = np.clip(np.searchsorted(t, times, side="right") - 1, 0, len(t) - 2)
    u = (times - t[j]) / (t[j + 1] - t[j])
    a, b = k[j], k[j + 1]
    omega = np.arccos(np.clip(np.sum(a * b, axis=1), -1.0, 1.0))
    small = omega < 1e-12
    s = np.where(small, 1.0, np.sin(omega))
    wa = np.where(small, 1 - u, np.sin((1 - u) * omega) / s)
    wb = np.where(small, u, np.sin(u * omega) / s)
    v = wa[:, None] * a + wb[:, None] * b
    v /= np.linalg.norm(v, axis=1)[:, None]
    return v, (1 - u) * flux[j] + u * flux[j + 1]


def beam_frame(theta, phi, psi, k):
    """(rho, sigma) of directions k in the antenna frames R_z(phi) R_y(theta) R_z(psi)."""
    ct, st, cp, sp, cs, ss = np.cos(theta), np.sin(theta), np.cos(phi), np.sin(phi), np.cos(psi), np.sin(psi)
    e_theta = np.stack([cp * ct * cs - sp * ss, sp * ct * cs + cp * ss, -st * cs], axis=1)
    e_phi = np.stack([-cp * ct * ss - sp * cs, -sp * ct * ss + cp * cs, st * ss], axis=1)
    p = np.stack([st * cp, st * sp, ct], axis=1)
    x, y, z = np.sum(k * e_theta, 1), np.sum(k * e_phi, 1), np.sum(k * p, 1)
    return np.arctan2(np.hypot(x, y), z), np.arctan2(y, x)


def analytic_beam(table, name):
    """B(rho, sigma) of a [beams.NAME] table of type gaussian or elliptical, its rho_max, its widest FWHM."""
    kind = table.get("type", "gaussian")
    if kind == "gaussian":
        fx = fy = math.radians(table["fwhm_deg"])
        angle = 0.0
    elif kind == "elliptical":
        fx, fy = math.radians(table["fwhm_x_deg"]), math.radians(table["fwhm_y_deg"])
        angle = math.radians(table.get("angle_deg", 0.0))
    else:
        raise Refused(f"[beams.{name}] type = {kind!r}: the beam map compares with Gaussian and elliptical beams only")
    if table.get("cross_polar", 0.0) != 0.0 or "mueller" in table:
        raise Refused(f"[beams.{name}]: the beam map compares with beams of no cross-polarization only")
    to_sigma = 1.0 / math.sqrt(8.0 * math.log(2.0))
    ax, ay = 0.5 / (fx * to_sigma) ** 2, 0.5 / (fy * to_sigma) ** 2
    rho_max = math.radians(table.get("rho_max_deg", 0.0)) or 2.5 * max(fx, fy)

    def b(rho, sigma):
        u, v = rho * np.cos(sigma - angle), rho * np.sin(sigma - angle)
        return np.exp(-(ax * u * u + ay * v * v))

    return b, rho_max, max(fx, fy)


def cap_integral(b, rho_max):
    """Omega~: the integral of b over the cap rho <= rho_max (sin rho d rho d sigma)."""
    nodes, weights = np.polynomial.legendre.leggauss(64)
    panels = 16
    edges = np.linspace(0.0, rho_max, panels + 1)
    sigma = np.linspace(0.0, 2 * math.pi, 720, endpoint=False)
    total = 0.0
    for lo, hi in zip(edges[:-1], edges[1:]):
        rho = 0.5 * (hi - lo) * nodes + 0.5 * (hi + lo)
        ring = b(rho[:, None], sigma[None, :]).mean(axis=1) * 2 * math.pi
        total += 0.5 * (hi - lo) * np.sum(weights * ring * np.sin(rho))
    return total


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("config", help="the simulation file")
    ap.add_argument("run", help="the run's output directory (its tod.h5)")
    ap.add_argument("--radius", type=float, default=2.0, help="compare within this many FWHM of the source (2)")
    ap.add_argument("--plot", help="write the recovered and input beam maps to this PNG")
    ap.add_argument("--subtract", metavar="RUN", help="subtract this run's TOD (the sky alone) instead of baselines")
    args = ap.parse_args()
    try:
        import h5py

        with open(args.config, "rb") as f:
            config = tomllib.load(f)
        scan = config.get("scan", {})
        if scan.get("type") != "ces":
            raise Refused(f"{args.config}: [scan] type must be 'ces' (a raster with az sweeps)")
        rate = float(scan.get("sample_rate_hz", 20.0))
        sweep = float(scan.get("az_throw_deg", 720.0)) / float(scan.get("az_speed_deg_s", 1.0)) * rate
        name, t_track, k_track, f_track = read_track(config, args.config)
        beams = {n: b for n, b in config.get("beams", {}).items() if b.get("type") not in ("sequence", "plate")}
        if len(beams) != 1:
            raise Refused(f"{args.config}: the beam map takes a file with one beam, found {len(beams)}")
        (beam_name, table), = beams.items()
        b, rho_max, fwhm = analytic_beam(table, beam_name)
        omega = cap_integral(b, rho_max)
        peak_of = None
        rows = []
        sky_alone = h5py.File(os.path.join(args.subtract, "tod.h5"), "r") if args.subtract else None
        with h5py.File(os.path.join(args.run, "tod.h5"), "r") as tod:
            for det in tod:
                g = tod[det]
                if "theta" not in g:
                    raise Refused(f"{args.run}/tod.h5: {det} has no pointing; run with [output] tod_pointing = true")
                d = np.asarray(g["signal"], dtype=float)
                theta, phi, psi = (np.asarray(g[c], dtype=float) for c in ("theta", "phi", "psi"))
                scale = 0.5 * float(g.attrs["gain"]) * (1.0 + float(g.attrs["epsilon"])) / omega
                times = np.arange(d.size) / rate
                k, flux = source_at(times, t_track, k_track, f_track)
                rho, sigma = beam_frame(theta, phi, psi, k)
                model = np.where(rho <= rho_max, scale * flux * b(rho, sigma), 0.0)
                # The sky under the source, sweep by sweep: a quadratic fitted far from it.
                cleaned = np.full(d.size, np.nan)
                n_sweeps = 0 if sky_alone is not None else int(math.ceil(d.size / sweep))
                if sky_alone is not None:
                    if det not in sky_alone or sky_alone[det]["signal"].shape != d.shape:
                        raise Refused(f"{args.subtract}/tod.h5: no {det} of {d.size} samples to subtract")
                    cleaned = d - np.asarray(sky_alone[det]["signal"], dtype=float)
                for s in range(n_sweeps):
                    lo, hi = int(round(s * sweep)), min(d.size, int(round((s + 1) * sweep)))
                    far = rho[lo:hi] > 3 * fwhm
                    if far.sum() < 20 or not np.any(rho[lo:hi] < args.radius * fwhm):
                        continue
                    x = np.arange(lo, hi, dtype=float) - 0.5 * (lo + hi)
                    fit = np.polynomial.polynomial.polyfit(x[far], d[lo:hi][far], 2)
                    cleaned[lo:hi] = d[lo:hi] - np.polynomial.polynomial.polyval(x, fit)
                near = (rho < args.radius * fwhm) & np.isfinite(cleaned)
                if near.sum() < 100:
                    raise Refused(f"{det}: {near.sum()} samples within {args.radius} FWHM of {name}: the scan misses it")
                peak = scale * float(np.max(f_track))
                peak_of = peak
                residual = cleaned[near] - model[near]
                x = rho[near] * np.cos(sigma[near])
                y = rho[near] * np.sin(sigma[near])
                core = rho[near] < fwhm

                def moments(w):
                    w = w[core]
                    cx, cy = np.sum(w * x[core]) / np.sum(w), np.sum(w * y[core]) / np.sum(w)
                    sx = math.sqrt(np.sum(w * (x[core] - cx) ** 2) / np.sum(w))
                    sy = math.sqrt(np.sum(w * (y[core] - cy) ** 2) / np.sum(w))
                    return cx, cy, sx, sy

                cd, cm = moments(cleaned[near]), moments(model[near])
                rows.append((det, int(near.sum()), math.sqrt(np.mean(residual**2)) / peak, np.abs(residual).max() / peak,
                             math.degrees(math.hypot(cd[0] - cm[0], cd[1] - cm[1])) * 60, cd[2] / cm[2], cd[3] / cm[3],
                             x, y, cleaned[near], model[near]))
    except (Refused, OSError, KeyError, ValueError, tomllib.TOMLDecodeError) as e:
        print(f"beam_map.py: {e}", file=sys.stderr)
        return 2
    print(f"{name}: peak response {peak_of:.4g} (the sky's units), beam {beam_name}, Omega~ {omega:.6g} sr")
    for det, n, rms, worst, off, wx, wy, *_ in rows:
        print(f"{det}: {n} samples within {args.radius:g} FWHM; recovered beam vs input: residual rms {rms:.2e}, "
              f"worst {worst:.2e} of the peak; centroid off by {off:.4f} arcmin; widths {wx:.4f}, {wy:.4f} of the input's")
    if args.plot:
        plot(rows, fwhm, args.radius, args.plot, peak_of)
    return 0


def plot(rows, fwhm, radius, path, peak):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    n = 41
    edges = np.linspace(-radius * fwhm, radius * fwhm, n + 1)
    fig, axes = plt.subplots(len(rows), 3, figsize=(12, 3.8 * len(rows)), squeeze=False)
    extent = np.degrees([edges[0], edges[-1], edges[0], edges[-1]]) * 60
    for r, (det, *_, x, y, data, model) in enumerate(rows):
        count, _, _ = np.histogram2d(y, x, bins=[edges, edges])
        maps = []
        for values in (data, model):
            total, _, _ = np.histogram2d(y, x, bins=[edges, edges], weights=values)
            with np.errstate(invalid="ignore", divide="ignore"):
                maps.append(np.where(count > 0, total / count / peak, np.nan))
        for c, (m, title) in enumerate(((maps[0], "recovered"), (maps[1], "input"), (maps[0] - maps[1], "difference"))):
            ax = axes[r][c]
            im = ax.imshow(m, origin="lower", extent=extent, cmap="RdBu_r" if c == 2 else "viridis")
            ax.set_title(f"{det}: {title} / peak")
            ax.set_xlabel("x (arcmin)")
            ax.set_ylabel("y (arcmin)")
            fig.colorbar(im, ax=ax)
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    print(f"wrote {path}")


if __name__ == "__main__":
    sys.exit(main())
