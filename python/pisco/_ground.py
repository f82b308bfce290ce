"""The horizon frame of the ground (docs/ground.md): the boresight of a constant-elevation scan there."""

import numpy as np


def horizon_pointing(az, el, boresight=0.0):
    """(theta, phi, psi) in the horizon frame of a boresight at azimuth `az` (from north towards east) and
    elevation `el`, turned by `boresight` about its line of sight (radians; arrays or numbers): theta =
    pi/2 - el, phi = -az (in [0, 2 pi)), psi = pi + boresight, so that theta' points to the zenith at
    boresight 0, as pisco-vk's ces scan orients it (CesScan::generate_horizon). Convolving a ground map
    (pisco.ground_sky) at these angles gives what the beams pick up from the ground."""
    az, el, boresight = np.broadcast_arrays(np.asarray(az, float), np.asarray(el, float), np.asarray(boresight, float))
    if not (np.all(np.isfinite(az)) and np.all(np.isfinite(boresight)) and np.all(np.abs(el) <= np.pi / 2)):
        raise ValueError("horizon_pointing: az and boresight must be finite, el within [-pi/2, pi/2]")
    theta = np.ascontiguousarray(np.pi / 2 - el)
    phi = np.ascontiguousarray(np.mod(-az, 2 * np.pi))
    psi = np.ascontiguousarray(np.pi + boresight)
    return theta, phi, psi
