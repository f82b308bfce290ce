#!/usr/bin/env python3
"""Case M's figure (docs/validation.md, "M"): the BB spectra of the binned and the deconvolved maps of
each pair kind, beside the r = 0.1 tensor BB, from the spectra `pisco-vk validate --case M
--report-dir DIR` writes under DIR/M. Needs numpy and matplotlib (Debian's python3-matplotlib).

Usage: plot_case_m.py DIR/M            (writes DIR/M/M_bb.png)
"""
import os
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402


def main():
    if len(sys.argv) != 2:
        sys.exit(__doc__)
    report = sys.argv[1]
    fig, ax = plt.subplots(figsize=(7, 4.5))
    colours = {"matched": "tab:gray", "pointing": "tab:blue", "beam": "tab:red"}
    ref = None
    for name, colour in colours.items():
        for kind, style in (("binned", "-"), ("deconvolved", "--")):
            path = os.path.join(report, name, f"spectra_{kind}.txt")
            if not os.path.exists(path):
                sys.exit(f"plot_case_m: {path} is missing: run pisco-vk validate --case M --report-dir first")
            d = np.loadtxt(path)
            l, bb = d[:, 0], np.abs(d[:, 3])
            ref = d[:, 7]
            if name == "matched" and kind == "binned":
                continue  # zero to rounding: nothing to draw on a log scale
            ax.loglog(l, np.maximum(bb, 1e-12), style, color=colour, label=f"{name}, {kind}")
    ax.loglog(l, ref, ":", color="black", label="r = 0.1 tensor BB")
    ax.set_xlabel("multipole l")
    ax.set_ylabel("|D_l^BB| (uK^2)")
    ax.set_title("Case M: BB leaked by mismatched pairs, binned against deconvolved")
    ax.legend(fontsize=8)
    fig.tight_layout()
    out = os.path.join(report, "M_bb.png")
    fig.savefig(out, dpi=110)
    print(f"plot_case_m: wrote {out}")


if __name__ == "__main__":
    main()
