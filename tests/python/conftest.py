"""Shared pieces of the Python package's tests (run through ctest label `python`: run_pytest.py)."""

import os

import numpy as np
import pytest

# PISCO_REQUIRE_PEERS=1 (set by .ci/run): a test that skips (a peer package missing, importorskip, no
# device) fails instead, with the reason, so that a run cannot pass with the frameworks untested
# (docs/validation.md, "What a run must not skip"). A `skipif` marker states a condition of the machine
# the test cannot run under (another platform, a sanitizer's allocator) and keeps its skip.
REQUIRE_PEERS = os.environ.get("PISCO_REQUIRE_PEERS") == "1"


def _skip_to_failure(report, what, allowed=()):
    if REQUIRE_PEERS and report.skipped and not hasattr(report, "wasxfail"):
        reason = report.longrepr[2] if isinstance(report.longrepr, tuple) else str(report.longrepr)
        if any(a and a in reason for a in allowed):
            return
        report.outcome = "failed"
        report.longrepr = f"{what} skipped in a run that requires every peer package (PISCO_REQUIRE_PEERS=1): {reason}"


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_makereport(item, call):
    outcome = yield
    allowed = [m.kwargs.get("reason", "") for m in item.iter_markers("skipif")]
    _skip_to_failure(outcome.get_result(), item.nodeid, allowed)


@pytest.hookimpl(hookwrapper=True)
def pytest_make_collect_report(collector):
    outcome = yield
    _skip_to_failure(outcome.get_result(), collector.nodeid)

def smooth_sky_alm(lmax, seed, smoothing_fwhm):
    """A band-limited polarized sky as healpy a_lm (T, E, B): C_l ~ 1 / (l (l + 1)), E at 0.3 and B at
    0.1 of T, smoothed by a Gaussian of `smoothing_fwhm` (radians), no monopole."""
    import healpy as hp

    ell = np.arange(lmax + 1)
    cl = np.zeros(lmax + 1)
    cl[2:] = 1.0 / (ell[2:] * (ell[2:] + 1.0))
    window = hp.gauss_beam(smoothing_fwhm, lmax=lmax) ** 2
    np.random.seed(seed)
    alm = np.array([hp.synalm(cl * f * window, lmax=lmax) for f in (1.0, 0.3, 0.1)])
    alm[:, hp.Alm.getidx(lmax, 0, 0)] = 0
    return alm


def gaussian_blm(lmax, fwhm, epsilon=0.0, sign=1.0):
    """A Gaussian beam polarized along its frame's x axis as the (T, E, B) a_lm (mmax = 2) that ducc0's
    total convolution takes, TOAST's and litebird_sim's convention (-sqrt 2 on E and B): with it,
    ducc0 returns (1 + epsilon) I + (1 - epsilon)(Q cos 2psi + U sin 2psi) of the smoothed sky.
    sign = -1 turns the polarization by 90 deg (the B detector of a pair in its A's frame)."""
    import healpy as hp

    ell = np.arange(lmax + 1)
    bl = hp.gauss_beam(fwhm, lmax=lmax, pol=True)
    blm = np.zeros((3, hp.Alm.getsize(lmax, 2)), dtype=np.complex128)
    blm[0, hp.Alm.getidx(lmax, ell, 0)] = np.sqrt((2 * ell + 1) / (4 * np.pi)) * bl[:, 0] * (1 + epsilon)
    lp = ell[2:]
    e = np.sqrt((2 * lp + 1) / (32 * np.pi)) * bl[2:, 1] * (1 - epsilon) * sign
    blm[1, hp.Alm.getidx(lmax, lp, 2)] = -np.sqrt(2) * e
    blm[2, hp.Alm.getidx(lmax, lp, 2)] = -np.sqrt(2) * 1j * e
    return blm


def offset_elliptical_blm(lmax, mmax, fwhm, ellipticity, psi_ell, psi_pol=0.0, cross_polar_leakage=0.0,
                          offset=0.0, offset_angle=0.0):
    """An elliptical polarized Gaussian as litebird_sim's builder makes it (ducc0's convention: the
    major axis at psi_ell and the polarization at psi_pol from the frame's x axis), its centre moved
    `offset` off the pole (towards the direction `offset_angle`, by healpy's rotate_alm), kept to m <=
    mmax: (3, n) b_lm. With an offset, every m holds coefficients, odd m included, so that a beam
    turned by 180 deg is another beam. (ducc0's rotate_alm, healpy's conventions: a hundred times faster
    than healpy's own at lmax 768.)"""
    import ducc0
    import healpy as hp
    from litebird_sim.beam_synthesis import gauss_beam_to_alm

    full = np.array(gauss_beam_to_alm(lmax=lmax, mmax=lmax if offset else mmax, fwhm_rad=fwhm,
                                      ellipticity=ellipticity, psi_ell_rad=psi_ell, psi_pol_rad=psi_pol,
                                      cross_polar_leakage=cross_polar_leakage).values, dtype=np.complex128)
    if not offset:
        return full
    full = np.array([ducc0.sht.rotate_alm(row, lmax, -offset_angle, offset, offset_angle, nthreads=2) for row in full])
    return np.array([hp.resize_alm(row, lmax, lmax, lmax, mmax) for row in full])


def relative_rms(test, reference):
    test, reference = np.asarray(test), np.asarray(reference)
    return float(np.sqrt(np.mean((test - reference) ** 2) / np.mean(reference**2)))


def assert_everywhere(test, reference, away, bar):
    """The relative RMS of `test` against `reference` held to `bar` on the samples `away` from the poles
    and on those near them, each apart (docs/physics.md, "The quadrature"); both figures printed."""
    test, reference = np.asarray(test), np.asarray(reference)
    far = relative_rms(test[away], reference[away])
    if np.all(away):
        assert far <= bar
        return
    near = relative_rms(test[~away], reference[~away])
    print(f"  beyond 10 deg of the poles: {far:.2e}; within: {near:.2e} ({np.count_nonzero(~away)} samples)")
    assert far <= bar and near <= bar


@pytest.fixture
def tmp_out(tmp_path):
    return tmp_path
