"""The accuracy map (tools/accuracy_map.py; docs/validation.md, "L"), run small: NSIDE 64, 3, 6 and 10
pixels per FWHM, sky band limits 2 NSIDE and 3 NSIDE - 1, on every backend present. The tool itself
holds the bars (--check): with >= 6 pixels per FWHM, at both band limits, on the polar copy, the TOD is
within 1e-4 of its RMS of the exact harmonic smoothing at every colatitude and within 2e-5 RMS,
and the plain sum misses the pole by more than 1e-3 (so the check can fail); with --beam-types, every kind
of beam on a grid (elliptical, b_lm, GRASP file, beamsor file) at its default step is within 1e-4 of its
converged TOD at every colatitude, for both band limits."""

import json
import os
import subprocess
import sys

TOOL = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..", "tools", "accuracy_map.py")


def test_accuracy_map_holds_the_bars(tmp_path):
    out = tmp_path / "map"
    done = subprocess.run([sys.executable, TOOL, "--nside", "64", "--per-fwhm", "3", "6", "10", "--bands", "2", "3",
                           "--beam-types", "--out", str(out), "--check"], capture_output=True, text=True)
    print(done.stdout)
    print(done.stderr)
    assert done.returncode == 0, done.stdout[-2000:] + done.stderr[-2000:]
    data = json.loads((out / "accuracy.json").read_text())
    assert {r["backend"] for r in data["rows"]} >= {"cpu"}
    assert (out / "accuracy.png").stat().st_size > 10000
    assert "| 128 (2 NSIDE) | 6 |" in (out / "accuracy.md").read_text()
    assert "| 191 (3 NSIDE) | 6 |" in (out / "accuracy.md").read_text()
    assert {r["beam"] for r in data["beam_rows"]} == {"elliptical", "b_lm", "GRASP file", "beamsor file"}
    assert {r["lmax"] for r in data["beam_rows"]} == {128, 191}
