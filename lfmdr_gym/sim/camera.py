"""The MRCLAM robots' camera as env keywords: the preset of ``LFMDR-Camera-v0``.

The figures were measured from the four MRCLAM runs in ``shared/data/mrclam`` (DS1, DS2, DS3,
DS6; 112,393 landmark readings, 7,156 images of three or more landmarks) by
``python -m lfmdr_gym.datasets.camera_model`` (:mod:`lfmdr_gym.datasets.camera_model`, which says
how: each image's pose fitted to its own readings and the landmarks' ground truth, studentised
residuals, robust spreads). Its output::

    field of view: 67.7 deg (twice the largest |bearing|)
    range limit: 7.32 m (99th percentile of the ranges); least range 1.09 m (not modelled)
    bearing noise: 0.27 deg (robust sd of the residuals; bias -0.01 deg, not modelled)
    range noise: 0.106 m at ranges <= 3.54 m (0.128 m over all ranges; bias +0.001 m)
    per run: DS1 0.29 deg, 0.123 m; DS2 0.26 deg, 0.118 m; DS3 0.24 deg, 0.123 m;
             DS6 0.30 deg, 0.047 m

The range noise is the spread at the distances of the simulated 2.5 m arena (up to its
diagonal); the camera's grows with distance (0.08 m below 1.5 m, 0.14-0.18 m beyond 3.5 m), and
its least range, about 1 m, has no keyword in the environment. DS6's low range figure is probably its
clustered layout: its images of three landmarks see one cluster, at nearly one range and
bearing, so an error common to the image (a scale error of the barcode size) moves the fitted
pose rather than the residuals; the other runs agree with each other. ``line_of_sight`` is on because
a camera reads no barcode through another landmark (not a measured figure).
"""

from __future__ import annotations

from types import MappingProxyType

__all__ = ["CAMERA_PRESET"]

CAMERA_PRESET = MappingProxyType({
    "fov_deg": 67.7,            # measured: 2 x max |bearing| over the runs' readings
    "max_range": 7.32,          # measured: 99th percentile of the runs' ranges [m]
    "bearing_noise_deg": 0.27,  # measured: robust sd of the bearing residuals
    "range_noise": 0.106,       # measured: robust sd of the range residuals up to 3.54 m [m]
    "line_of_sight": True,      # a camera does not see through the cylinders
})
"""Env keywords of ``LFMDR-Camera-v0`` beyond ``sensor="range-bearing"`` (see the module
docstring for where each figure comes from; ``gym.make(..., fov_deg=...)`` overrides one)."""
