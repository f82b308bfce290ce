#!/usr/bin/env python3
"""Plots of a `pisco-vk run` output directory: PNG maps (mollview and a zoomed gnomview) and D_l
spectra with the input's and the r = 0.1 tensor BB reference curve.

    /usr/bin/python3 tools/pisco_plot.py [--dpi N] [--no-gnomview] [--] OUTPUT_DIR

(`pisco-vk run` gives "--" before the directory, so that a directory named like "-x" is not an option.)

Needs Debian's python3-healpy and python3-matplotlib (they live under /usr/bin/python3); exits with
status 3 without them, 4 when a file cannot be written (a full disk), 128 + N when stopped by signal N.
Each PNG is written under a temporary name and renamed when complete, so that no half-written plot is
ever left (the temporary is removed on any failure or signal).
"""
import argparse
import errno
import os
import re
import secrets
import signal
import sys

UNSEEN = -1.6375e30


def fail(message, status):
    print(f"pisco_plot: {message}", file=sys.stderr)
    sys.exit(status)


class Stopped(Exception):
    """A SIGINT, SIGTERM or SIGHUP: unwind, removing the temporary file being written."""

    def __init__(self, signum):
        super().__init__(signum)
        self.signum = signum


def on_signal(signum, _frame):
    raise Stopped(signum)


# The suffix of this process's temporary files: pisco-vk passes its own (--temporary-suffix), which
# its output directory's lock records; run alone, a name no user's file has.
TEMPORARY_SUFFIX = f".tmp-pisco-{os.getpid()}-{secrets.token_hex(8)}"


def save(fig, path, dpi):
    """fig as the PNG `path`, whole or not at all (PISCO_TEST_FAULT=write-fail:NAME: a full disk)."""
    temporary = f"{path}{TEMPORARY_SUFFIX}"
    try:
        fig.savefig(temporary, dpi=dpi, bbox_inches="tight", format="png")
        if os.environ.get("PISCO_TEST_FAULT") == "write-fail:" + os.path.basename(path):
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC), path)
        os.replace(temporary, path)
    except BaseException:
        try:
            os.remove(temporary)
        except OSError:
            pass
        raise


def load_spectra(path):
    import numpy as np
    data = np.loadtxt(path, comments="#", ndmin=2)
    if data.shape[1] < 7:
        fail(f"{path}: expected columns l TT EE BB TE EB TB", 2)
    return data


def tensor_reference(script_dir, lmax):
    """0.1 times the r = 1 tensor BB template shipped in assets/spectra (None if absent)."""
    import numpy as np
    for base in (os.path.join(script_dir, "..", "assets"), os.path.join(script_dir, "..", "share", "pisco", "assets")):
        path = os.path.join(base, "spectra", "tensor_bb_r1.txt")
        if os.path.exists(path):
            t = np.loadtxt(path, comments="#", ndmin=2)
            t = t[t[:, 0] <= lmax]
            return t[:, 0], 0.1 * t[:, 1]
    return None


def plot_maps(out, dpi, gnomview):
    import healpy as hp
    import matplotlib.pyplot as plt
    import numpy as np
    path = os.path.join(out, "maps.fits")
    maps = hp.read_map(path, field=(0, 1, 2))
    unit = ""
    fig = plt.figure(figsize=(15, 4))
    for i, (m, name) in enumerate(zip(maps, "IQU")):
        hp.mollview(m, fig=fig.number, sub=(1, 3, i + 1), title=f"{name}", unit=unit, badcolor="lightgray")
    written = [os.path.join(out, "maps_mollview.png")]
    save(fig, written[-1], dpi)
    plt.close(fig)

    hits_path = os.path.join(out, "hits.fits")
    if os.path.exists(hits_path):
        hits = hp.read_map(hits_path)
        fig = plt.figure(figsize=(8, 5))
        hp.mollview(hits, fig=fig.number, title="hits", unit="samples", badcolor="lightgray")
        written.append(os.path.join(out, "hits_mollview.png"))
        save(fig, written[-1], dpi)
        plt.close(fig)
        if gnomview and hits.sum() > 0:
            # Centre the zoom on the hits-weighted mean direction of the observed region.
            nside = hp.npix2nside(hits.size)
            v = np.array(hp.pix2vec(nside, np.arange(hits.size))) @ hits
            lon, lat = hp.vec2ang(v / np.linalg.norm(v), lonlat=True)
            fig = plt.figure(figsize=(15, 4))
            for i, (m, name) in enumerate(zip(maps, "IQU")):
                hp.gnomview(m, fig=fig.number, sub=(1, 3, i + 1), rot=(lon[0], lat[0]), reso=2.0, xsize=600,
                            title=f"{name} (20 deg across)", badcolor="lightgray")
            written.append(os.path.join(out, "maps_gnomview.png"))
            save(fig, written[-1], dpi)
            plt.close(fig)
    return written


def plot_spectra(out, dpi, script_dir):
    import matplotlib.pyplot as plt
    path = os.path.join(out, "spectra.txt")
    if not os.path.exists(path):
        return []
    s = load_spectra(path)
    inp_path = os.path.join(out, "input_spectra.txt")
    inp = load_spectra(inp_path) if os.path.exists(inp_path) else None
    lmax = int(s[-1, 0])
    ref = tensor_reference(script_dir, lmax)
    fig, axes = plt.subplots(2, 3, figsize=(15, 7), sharex=True, gridspec_kw={"height_ratios": [3, 1]})
    for j, (name, col) in enumerate((("TT", 1), ("EE", 2), ("BB", 3))):
        ax, res = axes[0, j], axes[1, j]
        ax.plot(s[:, 0], s[:, col], label="out", lw=1)
        if inp is not None:
            n = min(len(inp), len(s))
            ax.plot(inp[:n, 0], inp[:n, col], ":", label="in", lw=1.5)
            res.plot(s[:n, 0], s[:n, col] - inp[:n, col], lw=1)
        if name == "BB" and ref is not None:
            ax.plot(ref[0], ref[1], "k--", label="r = 0.1 (tensor)", lw=1)
        if name != "TT":
            ax.set_yscale("symlog", linthresh=1e-6)
        ax.set_title(name)
        ax.legend(fontsize=8)
        res.set_xlabel(r"$\ell$")
        res.axhline(0, color="gray", lw=0.5)
    axes[0, 0].set_ylabel(r"$D_\ell$")
    axes[1, 0].set_ylabel("out - in")
    written = os.path.join(out, "spectra.png")
    save(fig, written, dpi)
    plt.close(fig)
    return [written]


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("output_dir")
    parser.add_argument("--dpi", type=int, default=100)
    parser.add_argument("--no-gnomview", action="store_true")
    parser.add_argument("--temporary-suffix", default=None, help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.temporary_suffix is not None:
        if not re.fullmatch(r"\.tmp-pisco-[0-9]+-[0-9a-f]{16}", args.temporary_suffix):
            fail(f"--temporary-suffix: expected .tmp-pisco-PID-TOKEN, got {args.temporary_suffix!r}", 2)
        global TEMPORARY_SUFFIX
        TEMPORARY_SUFFIX = args.temporary_suffix
    # The signals that would end the process: its temporary file removed first. One ignored when the
    # plot started (nohup) stays ignored.
    for s in (signal.SIGINT, signal.SIGTERM, signal.SIGHUP, signal.SIGQUIT, signal.SIGUSR1, signal.SIGUSR2,
              signal.SIGALRM):
        if signal.getsignal(s) != signal.SIG_IGN:
            signal.signal(s, on_signal)
    try:
        import matplotlib
        matplotlib.use("Agg")
        import healpy  # noqa: F401
    except ImportError as e:
        fail(f"cannot plot: {e} (install Debian's python3-healpy and python3-matplotlib, run /usr/bin/python3)", 3)
    if not os.path.exists(os.path.join(args.output_dir, "maps.fits")):
        fail(f"{os.path.join(args.output_dir, 'maps.fits')}: no such file", 2)
    script_dir = os.path.dirname(os.path.abspath(__file__))
    import warnings
    warnings.filterwarnings("ignore")
    try:
        for f in plot_maps(args.output_dir, args.dpi, not args.no_gnomview) + plot_spectra(args.output_dir, args.dpi, script_dir):
            print(f"plots: wrote {f}")
    except OSError as e:
        fail(f"{e.filename or args.output_dir}: {e.strerror or e}", 4)


if __name__ == "__main__":
    try:
        main()
    except Stopped as stopped:
        sys.exit(128 + stopped.signum)
