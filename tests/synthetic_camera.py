"""A synthetic bearing camera for the mappers' tests (no simulator): what a camera of a given
field of view, range and noise reads of known objects from known poses."""

import numpy as np
from synthetic_walk import sensed


def camera_bearings(P, poses, fov_deg, max_range, noise_deg, rng):
    """``(X, seen)``: the (M, 2N) bearing history (cos, sin per step, 0 where unseen) of the
    objects ``P`` (M, 2) from ``poses`` (N, 3: x, y, heading), and the (M, N) seen flags. An
    object is seen within ``fov_deg`` of the heading and ``max_range`` (None: any range); its
    bearing gets Gaussian noise of ``noise_deg``, drawn from ``rng``."""
    _, b, seen = sensed(P, poses, fov_deg, max_range)
    b = b + np.radians(noise_deg) * rng.standard_normal(b.shape)
    X = (np.stack([np.cos(b), np.sin(b)], -1) * seen[..., None]).reshape(len(P), -1)
    return X, seen
