"""examples/python/ run end to end (shortened) and write their map PNGs."""

import os
import re
import subprocess
import sys

import pytest

EXAMPLES = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..", "examples", "python")


@pytest.mark.parametrize("script", ["toast_pipeline.py", "litebird_sim_pipeline.py"])
def test_example_runs_and_draws_its_map(script, tmp_path):
    out = tmp_path / "out"
    done = subprocess.run(
        [sys.executable, os.path.join(EXAMPLES, script), "--hours", "0.5", "--nside-sky", "128", "--backend", "cpu",
         "--out", str(out)],
        capture_output=True, text=True, timeout=300, cwd=tmp_path)
    assert done.returncode == 0, done.stdout + done.stderr
    assert (out / "binned_map.png").stat().st_size > 10000
    assert (out / "binned_map.fits").exists()
    residual = re.search(r"input: I ([\d.]+), Q ([\d.]+), U ([\d.]+)", done.stdout)
    assert residual, done.stdout
    # Half an hour of scan: sparse coverage, a coarse map; still the smoothed input sky in I, Q and U.
    assert all(float(r) < 0.3 for r in residual.groups()), done.stdout
