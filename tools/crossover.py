#!/usr/bin/env python3
"""Where pixel space wins: PISCO-VK against ducc0's harmonic total convolution, per core (docs/validation.md, G).

Run it with the python tests' environment and the package of a build tree:

    PYTHONPATH=build/python build/python-venv/bin/python tools/crossover.py [--quick] [--out DIR]

It times, on one thread each and in one run, every PISCO-VK backend present (``pisco.devices()``:
cpu, vulkan, simd, cuda; vulkan's lavapipe held to one thread with ``LP_NUM_THREADS=1``) and ducc0's
``totalconvolve.Interpolator`` (litebird_sim's ``MuellerConvolver`` for a non-ideal half-wave plate)
on the same workloads:

- band limits lmax 383, 767, 1535, PISCO-VK's sky at NSIDE (lmax + 1) / 3 (128, 256, 512) and a beam
  of FWHM 3 pixels summed out to 2.5 FWHM (about 180 pixels a disc at every lmax);
- beams: round (a Gaussian; ducc0 kmax 2), elliptical (FWHM ratio 1.4; kmax 8) and strongly
  asymmetric (an elliptical main lobe, a sidelobe at 1.2 FWHM and a quadrupole cross-polar lobe;
  kmax 20). ducc0's beam coefficients come from the beam's intensity map (healpy's map2alm up to
  m = kmax; its polarized coefficients are the Gaussian's): its cost depends on lmax, kmax and the
  samples, not on the values;
- without a plate and with a generic one (the ideal plate plus leakage in all 16 entries; PISCO-VK's
  aperture plate, litebird_sim's MuellerConvolver);
- ducc0 at epsilon 1e-5 (its accuracy parameter), PISCO-VK's default beam grid (FWHM / 20): both
  about 1e-5 relative to the TOD (tools/ducc0_compare.py, tools/hwp_compare.py measure the agreement).

What is measured, per code and workload: the set-up of one detector's beam (PISCO-VK: its beamsor
prepared by the engine, beside the sky's own set-up; ducc0: the Interpolator or MuellerConvolver, one
per beam) and the time per sample over a scan of ``--samples`` samples (a spiral scan: neighbouring
samples see neighbouring discs, as in real scans). The total time of D detectors with distinct beams
and N samples each is then set-up + D (beam set-up + N t_sample), which the tool checks against a
direct run at one point (``check`` rows). The crossover map gives, for 1 and 100 detectors and N from
1e4 to 1e7, the ratio of ducc0's time to the fastest PISCO-VK backend's: above 1, pixel space wins.

Writes crossover.md (the tables) and crossover.png (the map) into --out; tools/gpu_steps.sh runs it
on GPU machines, where the device backends fill their columns.
"""

import argparse
import os
import sys
import time

os.environ.setdefault("LP_NUM_THREADS", "1")  # lavapipe: one core, as the others (before Vulkan loads)
os.environ.setdefault("OMP_NUM_THREADS", "1")

import numpy as np  # noqa: E402

LMAXES = (383, 767, 1535)
BEAMS = {"round": 2, "elliptical": 8, "asymmetric": 20}  # ducc0's kmax for each
GENERIC_PLATE = np.diag([1.0, 1.0, -1.0, -1.0]) + np.array([[-0.02, 0.012, -0.008, 0.005],
                                                           [0.021, -0.03, 0.017, -0.011],
                                                           [-0.015, 0.009, 0.025, 0.04],
                                                           [0.007, -0.02, 0.033, 0.02]])
EPSILON = 1e-5


def beam_geometry(lmax):
    """NSIDE, FWHM and rho_max (radians) of a workload."""
    import healpy as hp

    nside = (lmax + 1) // 3
    fwhm = 3 * hp.nside2resol(nside)
    return nside, fwhm, 2.5 * fwhm


def beam_field(kind, fwhm):
    """The beam's intensity at (rho, sigma), and its cross-polar part, for PISCO-VK and healpy alike."""
    s = fwhm / np.sqrt(8 * np.log(2))
    if kind == "round":
        return lambda x, y: (np.exp(-(x * x + y * y) / (2 * s * s)), 0.0 * x)
    sx, sy = 1.2 * s, s / 1.2  # elliptical: FWHM ratio 1.44
    main = lambda x, y: np.exp(-(x * x / (2 * sx * sx) + y * y / (2 * sy * sy)))  # noqa: E731
    if kind == "elliptical":
        return lambda x, y: (main(x, y), 0.0 * x)
    side = lambda x, y: 0.02 * np.exp(-((x - 1.2 * fwhm) ** 2 + y * y) / (2 * (0.6 * s) ** 2))  # noqa: E731
    return lambda x, y: (main(x, y) + side(x, y), 0.03 * main(x, y) * (x * x - y * y) / (x * x + y * y + s * s))


def pisco_beam(pisco, kind, fwhm, rho_max):
    if kind == "round":
        return pisco.Beamsor.gaussian(fwhm, rho_max=rho_max)
    f = beam_field(kind, fwhm)

    def field(rho, sigma):
        x, y = rho * np.cos(sigma), rho * np.sin(sigma)
        b, c = f(x, y)
        m = np.zeros((4, 4))
        m[0, 0] = m[1, 1] = m[2, 2] = m[3, 3] = b
        m[1, 2], m[2, 1] = c, -c  # a cross-polar response
        return m

    return pisco.Beamsor.from_field(field, rho_max, fwhm / 20, description=kind, feature_scale=fwhm / 2)


def ducc0_blm(kind, fwhm, lmax, kmax):
    """healpy-layout beam coefficients up to m = kmax: T from the beam's map, E and B the Gaussian's
    (times -sqrt 2, ducc0's convention)."""
    import healpy as hp

    ncoef = hp.Alm.getsize(lmax, kmax)
    blm = np.zeros((3, ncoef), dtype=np.complex128)
    l = np.arange(lmax + 1)
    bl = hp.gauss_beam(fwhm, lmax=lmax, pol=True)
    if kind == "round":
        blm[0, hp.Alm.getidx(lmax, l, 0)] = np.sqrt((2 * l + 1) / (4 * np.pi)) * bl[:, 0]
    else:
        nside = 1
        while hp.nside2resol(nside) > fwhm / 6:
            nside *= 2
        npix_cap = hp.query_disc(nside, [0, 0, 1], 3 * fwhm)
        theta, phi = hp.pix2ang(nside, npix_cap)
        x, y = theta * np.cos(phi), theta * np.sin(phi)
        m = np.zeros(hp.nside2npix(nside))
        m[npix_cap] = beam_field(kind, fwhm)(x, y)[0]
        m /= m.sum() * hp.nside2pixarea(nside)
        t = hp.map2alm(m, lmax=lmax, mmax=kmax, iter=0)
        blm[0] = t * np.sqrt(4 * np.pi)  # b_00 as the Gaussian's: unit integral
    lp = l[2:]
    e = np.sqrt((2 * lp + 1) / (32 * np.pi)) * bl[2:, 1]
    blm[1, hp.Alm.getidx(lmax, lp, 2)] = -np.sqrt(2) * e
    blm[2, hp.Alm.getidx(lmax, lp, 2)] = -np.sqrt(2) * 1j * e
    return blm


def spiral_scan(n, seed=3):
    """A scan: the boresight along a slowly precessing great circle, psi turning, neighbours close."""
    t = np.arange(n) / 100.0
    rng = np.random.default_rng(seed)
    theta = np.pi / 2 + 0.9 * np.sin(2 * np.pi * t / 60.0) * np.cos(2 * np.pi * t / 3600.0)
    phi = np.mod(2 * np.pi * t / 60.0 + 0.3 * np.sin(2 * np.pi * t / 3600.0) + rng.uniform(0, 1e-4, n), 2 * np.pi)
    psi = np.mod(2 * np.pi * t / 15.0, 2 * np.pi) - np.pi
    return theta, phi, psi


def random_sky_maps(nside, seed=1):
    rng = np.random.default_rng(seed)
    npix = 12 * nside * nside
    return [rng.normal(0, s, npix) for s in (1e-4, 3e-6, 3e-6)]


def time_pisco(pisco, backend, maps, kind, fwhm, rho_max, plate, scan, repeat_detectors=4):
    """(sky set-up s, per-detector set-up s, s per sample) of one PISCO-VK backend, one thread."""
    theta, phi, psi = scan
    sky = pisco.Sky.from_maps(maps)
    beams = [pisco_beam(pisco, kind, fwhm * (1 + 0.01 * k), rho_max) for k in range(repeat_detectors)]
    hwp = pisco.HalfWavePlate(mueller=GENERIC_PLATE) if plate else None

    def focal_plane(n):
        fp = pisco.FocalPlane()
        for k in range(n):
            fp.add(f"d{k}", beam=k, hwp=hwp)
        return fp

    # One thread where the backend runs host threads of its own (its capabilities say so).
    caps = next(b.capabilities for b in pisco.devices() if b.name == backend)
    options = dict(backend=backend, threads=1) if caps["worker_threads"] else dict(backend=backend)
    t0 = time.perf_counter()
    one = pisco.Engine(sky, beams[:1], focal_plane(1), **options)
    t1 = time.perf_counter()
    one.close()
    t2 = time.perf_counter()
    many = pisco.Engine(sky, beams, focal_plane(repeat_detectors), **options)
    t3 = time.perf_counter()
    per_detector = max((t3 - t2) - (t1 - t0), 0.0) / (repeat_detectors - 1)
    sky_setup = max((t1 - t0) - per_detector, 0.0)
    hwp_angle = np.mod(2 * np.pi * 2.0 * np.arange(len(theta)) / 100.0, 2 * np.pi) if plate else None
    out = np.empty(len(theta))
    many.convolve(0, theta[:1000], phi[:1000], psi[:1000], out=out[:1000],
                  hwp_angle=None if hwp_angle is None else hwp_angle[:1000])  # warm
    t4 = time.perf_counter()
    many.convolve(0, theta, phi, psi, out=out, hwp_angle=hwp_angle)
    t5 = time.perf_counter()
    assert np.all(np.isfinite(out))
    device = many.device
    many.close()
    return sky_setup, per_detector, (t5 - t4) / len(theta), device


def ducc0_convolver(slm, blm, lmax, kmax, plate):
    import ducc0

    if plate:
        from litebird_sim import MuellerConvolver

        return MuellerConvolver(slm=slm, blm=blm, mueller=GENERIC_PLATE, lmax=lmax, kmax=kmax,
                                single_precision=False, epsilon=EPSILON, nthreads=1)
    return ducc0.totalconvolve.Interpolator(sky=slm, beam=blm, separate=False, lmax=lmax, kmax=kmax,
                                            epsilon=EPSILON, nthreads=1)


def time_ducc0(slm, blm, lmax, kmax, plate, scan):
    """(per-beam set-up s, s per sample) of ducc0 (litebird_sim with a plate), one thread."""
    theta, phi, psi = scan
    ptg = np.stack([theta, phi, psi], axis=1)
    t0 = time.perf_counter()
    conv = ducc0_convolver(slm, blm, lmax, kmax, plate)
    t1 = time.perf_counter()
    if plate:
        alpha = np.mod(2 * np.pi * 2.0 * np.arange(len(theta)) / 100.0, 2 * np.pi)
        tod = conv.signal(ptg=ptg, alpha=alpha, strict_typing=False)
    else:
        tod = conv.interpol(ptg)[0]
    t2 = time.perf_counter()
    assert np.all(np.isfinite(tod))
    return t1 - t0, (t2 - t1) / len(theta)


def random_alm(lmax, seed=1):
    import healpy as hp

    rng = np.random.default_rng(seed)
    n = hp.Alm.getsize(lmax)
    l, m = hp.Alm.getlm(lmax)
    scale = 1.0 / np.maximum(l * (l + 1.0), 2.0)
    alm = (rng.normal(size=(3, n)) + 1j * rng.normal(size=(3, n))) * np.sqrt(scale)
    alm[:, m == 0] = alm[:, m == 0].real
    alm[:, l < 2] = 0.0
    return alm


def total(setup, per_det, per_sample, detectors, samples):
    return setup + detectors * (per_det + samples * per_sample)


def main():
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--quick", action="store_true", help="lmax 383 and 767 only, fewer samples (a few minutes)")
    p.add_argument("--smoke", action="store_true", help="lmax 95, round beam, 2000 samples: checks the tool runs")
    p.add_argument("--samples", type=int, default=100_000, help="samples timed per workload (default 1e5)")
    p.add_argument("--out", default=".", help="directory for crossover.md and crossover.png")
    p.add_argument("--backends", nargs="*", help="PISCO-VK backends (default: every one present)")
    p.add_argument("--from-table", metavar="CROSSOVER_MD",
                   help="no measurement: redraw the map and the tables from a report's measured components")
    args = p.parse_args()
    os.makedirs(args.out, exist_ok=True)
    if args.from_table:
        return redraw(args.from_table, args.out)

    import healpy as hp
    import pisco

    lmaxes, beams, samples = LMAXES, dict(BEAMS), args.samples
    if args.quick:
        lmaxes, samples = LMAXES[:2], min(samples, 50_000)
    if args.smoke:
        lmaxes, beams, samples = (95,), {"round": 2, "asymmetric": 20}, 2000
    present = [b.name for b in pisco.devices() if b.available]
    backends = args.backends or present
    missing = [b for b in backends if b not in present]
    if missing:
        raise SystemExit(f"crossover: backend(s) {', '.join(missing)} not available here "
                         f"({'; '.join(f'{b.name}: {b.detail}' for b in pisco.devices())})")
    import ducc0
    import litebird_sim

    os.makedirs(args.out, exist_ok=True)
    scan = spiral_scan(samples)
    rows = []  # (lmax, beam, plate, code, sky set-up, beam set-up, s/sample, device)
    started = time.perf_counter()
    for lmax in lmaxes:
        nside, fwhm, rho_max = beam_geometry(lmax)
        maps = random_sky_maps(nside)
        slm = random_alm(lmax)
        for kind, kmax in beams.items():
            blm = ducc0_blm(kind, fwhm, lmax, kmax)
            for plate in (False, True):
                if plate and lmax == 1535 and kind != "round" and not args.smoke:
                    continue  # litebird_sim with a plate at kmax >= 8 and lmax 1535: minutes a beam
                for backend in backends:
                    s, d, t, device = time_pisco(pisco, backend, maps, kind, fwhm, rho_max, plate, scan)
                    rows.append((lmax, kind, plate, f"pisco-vk {backend}", s, d, t, device))
                    print(f"lmax {lmax} {kind:<10} plate {plate!s:<5} pisco-vk {backend:<7} sky {s:7.3f} s, "
                          f"beam {d:7.3f} s, {t * 1e6:8.3f} us/sample ({device})", flush=True)
                d, t = time_ducc0(slm, blm, lmax, kmax, plate, scan)
                code = "litebird_sim MuellerConvolver" if plate else "ducc0 Interpolator"
                rows.append((lmax, kind, plate, code, 0.0, d, t, f"kmax {kmax}, epsilon {EPSILON:g}"))
                print(f"lmax {lmax} {kind:<10} plate {plate!s:<5} {code:<30} beam {d:7.3f} s, "
                      f"{t * 1e6:8.3f} us/sample (kmax {kmax})", flush=True)

    # A direct run against the model: 4 detectors x 4 times the timed samples, the fastest backend, round
    # beam, lowest lmax.
    lmax = lmaxes[0]
    nside, fwhm, rho_max = beam_geometry(lmax)
    sub = [r for r in rows if r[0] == lmax and r[1] == "round" and not r[2] and r[3].startswith("pisco")]
    best = min(sub, key=lambda r: r[6])
    long_scan = spiral_scan(4 * samples)
    s, d, t, _ = time_pisco(pisco, best[3].split()[1], random_sky_maps(nside), "round", fwhm, rho_max, False, long_scan)
    predicted = total(best[4], best[5], best[6], 4, 4 * samples)
    measured = total(s, d, t, 4, 4 * samples)
    check = (best[3], 4, 4 * samples, predicted, measured)

    write_report(args.out, rows, lmaxes, beams, check, time.perf_counter() - started, ducc0, litebird_sim, pisco)


def redraw(table, out):
    """The report again from the measured components of an earlier one (its first lines kept)."""
    rows, head, check = [], [], None
    with open(table) as f:
        text = f.read().splitlines()
    for line in text:
        cells = [c.strip() for c in line.strip().strip("|").split("|")]
        if len(cells) == 8 and cells[0].isdigit():
            rows.append((int(cells[0]), cells[1], cells[2] == "generic", cells[3], float(cells[4]), float(cells[5]),
                         float(cells[6]) * 1e-6, cells[7]))
        m = __import__("re").match(r"Model check: (.*), (\d+) detectors x (\d+) samples: predicted ([\d.]+) s, run ([\d.]+) s",
                                   line)
        if m:
            check = (m.group(1), int(m.group(2)), int(m.group(3)), float(m.group(4)), float(m.group(5)))
    head = text[0]
    lmaxes = tuple(sorted({r[0] for r in rows}))
    beams = {k: None for k in dict.fromkeys(r[1] for r in rows)}
    write_report(out, rows, lmaxes, beams, check, None, None, None, None, first_line=head)


def write_report(out, rows, lmaxes, beams, check, wall, ducc0, litebird_sim, pisco, first_line=None):
    import platform

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    cpu = "unknown CPU"
    try:
        with open("/proc/cpuinfo") as f:
            cpu = next(line.split(":", 1)[1].strip() for line in f if line.startswith("model name"))
    except (OSError, StopIteration):
        pass
    ns = np.logspace(4, 7, 31)
    if first_line is None:
        first_line = (f"Machine: {cpu}, {os.cpu_count()} hardware threads, {platform.system()} {platform.release()}; "
                      f"one thread per code. pisco {pisco.__version__}, ducc0 {ducc0.__version__}, litebird_sim "
                      f"{litebird_sim.__version__}. Wall time of the run: {wall:.0f} s.")
    lines = [first_line, "",
             "Measured components (set-up of the sky once, of each beam once, then per sample):", "",
             "| lmax | beam | plate | code | sky set-up s | beam set-up s | us/sample | device |",
             "|---|---|---|---|---|---|---|---|"]
    for r in rows:
        lines.append(f"| {r[0]} | {r[1]} | {'generic' if r[2] else 'none'} | {r[3]} | {r[4]:.3f} | {r[5]:.3f} | "
                     f"{r[6] * 1e6:.3f} | {r[7]} |")
    lines += ["", f"Model check: {check[0]}, {check[1]} detectors x {check[2]} samples: predicted "
              f"{check[3]:.2f} s, run {check[4]:.2f} s ({100 * (check[4] / check[3] - 1):+.0f}%).", "",
              "Crossover: time of ducc0 (litebird_sim with the plate) / time of the fastest PISCO-VK backend "
              "present, D detectors with distinct beams, N samples each (above 1: pixel space wins; "
              "N*: the samples per detector where the two are equal).", "",
              "| lmax | beam | plate | D | fastest pisco-vk | N=1e4 | N=1e5 | N=1e6 | N=1e7 | N* |",
              "|---|---|---|---|---|---|---|---|---|---|"]
    panels = []
    for kind in beams:
        for plate in (False, True):
            for detectors in (1, 100):
                grid = np.full((len(lmaxes), len(ns)), np.nan)
                for i, lmax in enumerate(lmaxes):
                    mine = [r for r in rows if r[0] == lmax and r[1] == kind and r[2] == plate]
                    ours = [r for r in mine if r[3].startswith("pisco")]
                    theirs = [r for r in mine if not r[3].startswith("pisco")]
                    if not ours or not theirs:
                        continue
                    h = theirs[0]
                    def t_ours(n, r):
                        return total(r[4], r[5], r[6], detectors, n)
                    best = min(ours, key=lambda r: t_ours(1e6, r))
                    ratio = np.array([total(0, h[5], h[6], detectors, n) / min(t_ours(n, r) for r in ours) for n in ns])
                    grid[i] = ratio
                    # N*: where D (h_beam + N h_t) = S + D (d + N t) for the best backend at large N.
                    denom = detectors * (h[6] - best[6])
                    nstar = (best[4] + detectors * (best[5] - h[5])) / denom if denom != 0 else np.inf
                    if nstar <= 0:
                        star = "pisco-vk wins at every N" if h[6] > best[6] else "ducc0 wins at every N"
                    else:
                        star = f"{nstar:.2g} ({'pisco-vk' if h[6] > best[6] else 'ducc0'} wins above)"
                    cells = [total(0, h[5], h[6], detectors, n) / min(t_ours(n, r) for r in ours)
                             for n in (1e4, 1e5, 1e6, 1e7)]
                    lines.append(f"| {lmax} | {kind} | {'generic' if plate else 'none'} | {detectors} | "
                                 f"{best[3].split()[1]} | " + " | ".join(f"{c:.2g}" for c in cells) + f" | {star} |")
                panels.append((kind, plate, detectors, grid))
    with open(os.path.join(out, "crossover.md"), "w") as f:
        f.write("\n".join(lines) + "\n")
    fig, axes = plt.subplots(len(panels) // 2, 2, figsize=(10, 2.2 * len(panels) // 2 + 1), squeeze=False,
                             constrained_layout=True)
    for ax, (kind, plate, detectors, grid) in zip(axes.flat, panels):
        im = ax.pcolormesh(ns, np.arange(len(lmaxes)), np.log10(grid), cmap="RdBu", vmin=-2, vmax=2,
                           shading="nearest")
        ax.set_xscale("log")
        ax.set_yticks(np.arange(len(lmaxes)))
        ax.set_yticklabels([str(l) for l in lmaxes])
        ax.set_title(f"{kind}, {'generic plate' if plate else 'no plate'}, {detectors} detector(s)", fontsize=8)
        if ax in axes[-1]:
            ax.set_xlabel("samples per detector", fontsize=8)
        ax.set_ylabel("lmax", fontsize=8)
    fig.colorbar(im, ax=axes, label="log10 (ducc0 time / pisco-vk time): blue, pixel space wins")
    fig.savefig(os.path.join(out, "crossover.png"), dpi=90)
    print("\n".join(lines))
    print(f"crossover: wrote {os.path.join(out, 'crossover.md')} and crossover.png")


if __name__ == "__main__":
    sys.exit(main())
