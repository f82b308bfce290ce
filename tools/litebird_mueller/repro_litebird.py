"""The hand check itself (docs/python.md, "With litebird_sim's own b_lm ... through litebird_sim's ideal or
generic plate ... the beam 0.3 deg off its axis differs by 8e-4"): tests/python/test_litebird.py's
test_beam_alms_match_litebird_sim set-up (three detectors; det0, det1 litebird_sim's elliptical b_lm,
det2 an elliptical beam 0.3 deg off its axis; lmax 768, mmax 12; sky lmax 512 / NSIDE 256; PISCO-VK at
FWHM/40 out to 3 deg) with litebird_sim's IdealHWP at 46 rpm and each detector's mueller_hwp, 2 minutes of
scan; litebird_sim's own add_convolved_sky_to_observations (MuellerConvolver) against
pisco.litebird.add_convolved_sky_to_observations, and both against the exact harmonic reference
(common.ExactMuellerConvolver: MuellerConvolver's algebra with its m shifts done in real space) per detector.
Usage: python repro_litebird.py [--plate ideal|generic] [--seconds 120]"""
import argparse
import logging
import shutil
import tempfile
import pathlib

import numpy as np

import litebird_sim as lbs
from litebird_sim.coordinates import rotate_coordinates_e2g
from litebird_sim.observation_utilities import _get_hwp_angle
from test_litebird import GENERIC, HWP_SPEED, IDEAL, convolve_beam_alms, observation
from common import Timer, exact_conv, fmt, stats

logging.getLogger().setLevel(logging.ERROR)
p = argparse.ArgumentParser()
p.add_argument("--plate", default="ideal", choices=["ideal", "generic"])
p.add_argument("--seconds", type=float, default=120.0)
args = p.parse_args()
tm = Timer()
m0 = IDEAL if args.plate == "ideal" else GENERIC
nside, lmax = 256, 512
lmax_beam, mmax = 768, 12
tmp = pathlib.Path(tempfile.mkdtemp(prefix="lbs_", dir=None))
obs = observation(tmp, ellipticity=(1.5, 1.3, 1.6), psi_deg=(30.0, -20.0, 75.0), seconds=args.seconds,
                  hwp=lbs.IdealHWP(ang_speed_radpsec=HWP_SPEED, start_angle_rad=0.3), mueller_hwp=m0)
alm, blms = convolve_beam_alms(obs, nside, lmax, lmax_beam, mmax)
alpha = np.asarray(_get_hwp_angle(obs=obs, hwp=None, pointing_dtype=np.float64), dtype=np.float64)
pointings, _ = obs.get_pointings("all")
print(f"{args.plate} plate at 46 rpm, {obs.tod.shape[0]} detectors x {obs.tod.shape[1]} samples "
      f"(setup {tm():.0f} s)")
print(f"  all detectors: pisco.litebird vs litebird_sim (MuellerConvolver): {fmt(stats(obs.pisco, obs.tod))}")
for k, name in enumerate(obs.name):
    p = rotate_coordinates_e2g(pointings[k])
    ptg = np.ascontiguousarray(np.stack([p[:, 0], np.mod(p[:, 1], 2 * np.pi), p[:, 2]], axis=1))
    ex, _ = exact_conv(alm, np.asarray(blms[name].values), lmax_beam, mmax, lmax, m0, ptg, alpha)
    print(f"  {name}: pisco vs litebird_sim {fmt(stats(obs.pisco[k], obs.tod[k]))}")
    print(f"  {name}: pisco vs exact        {fmt(stats(obs.pisco[k], ex))}")
    print(f"  {name}: litebird_sim vs exact {fmt(stats(obs.tod[k], ex))}", flush=True)
print(f"total {tm():.0f} s")
shutil.rmtree(tmp, ignore_errors=True)  # the observation's files, ours
