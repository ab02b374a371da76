"""uncertainty=True on a real STAR-loc sequence (loop-3d_s2: stereo, a calibration nothing was
chosen on): the floor the held-out anchors estimate turns the model's regions, which miss most
tags, into regions that hold most of them and stay sharp (issue 35)."""

import warnings

import numpy as np
import pytest
from paths import SHARED_DATA

from lfmdr_gym.datasets.starloc import read_starloc, scored_tags, starloc_survey
from lfmdr_gym.experiments.starloc import map_starloc
from mappers.core.uncertainty import chi2_quantile, mahalanobis_squared, rms_radius

SEQ = SHARED_DATA / "starloc" / "data" / "loop-3d_s2"


@pytest.mark.skipif(not SEQ.is_dir(), reason=f"STAR-loc data not found at {SEQ}")
def test_true_adds_the_floor_the_anchors_see_on_a_real_sequence():
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        r = map_starloc(SEQ, uncertainty=True)
        model = map_starloc(SEQ, uncertainty="model")
    survey = starloc_survey(SEQ)
    xyz = survey.set_index("landmark")[["x", "y", "z"]]
    tags = [t for t in scored_tags(read_starloc(SEQ, "range-bearing"), survey, r.anchors)
            if t in r.positions]
    assert len(tags) >= 30
    pos = np.array([r.positions[t] for t in tags])
    np.testing.assert_array_equal(pos, np.array([model.positions[t] for t in tags]))
    err = xyz.loc[tags].to_numpy(dtype=float) - pos
    cov = np.array([r.covariances[t] for t in tags])
    cov_model = np.array([model.covariances[t] for t in tags])
    added = cov - cov_model  # one isotropic floor for every tag
    floor = added[0, 0, 0]
    assert floor > 0
    np.testing.assert_allclose(added, np.broadcast_to(floor * np.eye(3), added.shape),
                               rtol=1e-6, atol=1e-9 * floor)
    inside = np.mean(mahalanobis_squared(err, cov) <= chi2_quantile(3))
    inside_model = np.mean(mahalanobis_squared(err, cov_model) <= chi2_quantile(3))
    sharpness = np.mean(rms_radius(cov)) / np.mean(np.linalg.norm(err, axis=1))
    assert inside_model < 0.5 and inside >= 0.8  # (0.89 of 38 tags when measured)
    assert sharpness <= 3.0
