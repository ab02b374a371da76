"""A synthetic bearing camera for the mappers' tests (no simulator): what a camera of a given
field of view, range and noise reads of known objects from known poses."""

import numpy as np


def camera_bearings(P, poses, fov_deg, max_range, noise_deg, rng):
    """``(X, seen)``: the (M, 2N) bearing history (cos, sin per step, 0 where unseen) of the
    objects ``P`` (M, 2) from ``poses`` (N, 3: x, y, heading), and the (M, N) seen flags. An
    object is seen within ``fov_deg`` of the heading and ``max_range`` (None: any range); its
    bearing gets Gaussian noise of ``noise_deg``, drawn from ``rng``."""
    d = P[:, None, :] - poses[None, :, :2]
    b = np.angle(np.exp(1j * (np.arctan2(d[..., 1], d[..., 0]) - poses[None, :, 2])))
    seen = np.abs(b) <= np.radians(fov_deg) / 2
    if max_range is not None:
        seen &= np.hypot(d[..., 0], d[..., 1]) <= max_range
    b = b + np.radians(noise_deg) * rng.standard_normal(b.shape)
    X = (np.stack([np.cos(b), np.sin(b)], -1) * seen[..., None]).reshape(len(P), -1)
    return X, seen
