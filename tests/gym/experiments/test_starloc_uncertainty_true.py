"""uncertainty=True on a real STAR-loc sequence (loop-3d_s2: stereo, a calibration nothing was
chosen on): the floor the held-out anchors estimate turns the model's regions, which miss most
tags, into regions that hold most of them and stay sharp (issue 35)."""

import warnings

import numpy as np
import pytest
from paths import SHARED_DATA
from starloc_scoring import inside, scored_errors, sharpness

from lfmdr_gym.experiments.starloc import map_starloc

SEQ = SHARED_DATA / "starloc" / "data" / "loop-3d_s2"


@pytest.mark.skipif(not SEQ.is_dir(), reason=f"STAR-loc data not found at {SEQ}")
def test_true_adds_the_floor_the_anchors_see_on_a_real_sequence():
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        r = map_starloc(SEQ, uncertainty=True)
        model = map_starloc(SEQ, uncertainty="model")
    tags, err, cov = scored_errors(SEQ, r)
    assert len(tags) >= 30
    np.testing.assert_array_equal(np.array([r.positions[t] for t in tags]),
                                  np.array([model.positions[t] for t in tags]))
    cov_model = np.array([model.covariances[t] for t in tags])
    added = cov - cov_model  # one isotropic floor for every tag
    floor = added[0, 0, 0]
    assert floor > 0
    np.testing.assert_allclose(added, np.broadcast_to(floor * np.eye(3), added.shape),
                               rtol=1e-6, atol=1e-9 * floor)
    assert inside(err, cov_model) < 0.5 and inside(err, cov) >= 0.8  # (0.89 of 38 tags measured)
    assert sharpness(err, cov) <= 3.0
