"""The scored tags of a STAR-loc map with their errors and covariances, and the regions' coverage
and sharpness (issue 35), for the tests that check uncertainty on real sequences."""

from __future__ import annotations

import numpy as np

from lfmdr_gym.datasets.starloc import read_starloc, scored_tags, starloc_survey
from mappers.core.uncertainty import chi2_quantile, mahalanobis_squared, rms_radius


def scored_errors(seq, result) -> tuple[list[int], np.ndarray, np.ndarray]:
    """``(tags, errors (T, 3), covariances (T, 3, 3))`` of the scored tags ``result`` (a
    ``map_starloc`` result of the sequence folder ``seq``) placed: survey minus map."""
    survey = starloc_survey(seq)
    xyz = survey.set_index("landmark")[["x", "y", "z"]]
    tags = [t for t in scored_tags(read_starloc(seq, "range-bearing"), survey, result.anchors)
            if t in result.positions]
    err = xyz.loc[tags].to_numpy(dtype=float) - np.array([result.positions[t] for t in tags])
    return tags, err, np.array([result.covariances[t] for t in tags])


def inside(err: np.ndarray, cov: np.ndarray) -> float:
    """The share of errors inside their 95 % regions."""
    return float(np.mean(mahalanobis_squared(err, cov) <= chi2_quantile(3)))


def sharpness(err: np.ndarray, cov: np.ndarray) -> float:
    """The mean RMS radius of the 95 % regions over the mean error."""
    return float(np.mean(rms_radius(cov)) / np.mean(np.linalg.norm(err, axis=1)))
