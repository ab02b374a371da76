"""map_mrclam_run(uncertainty=True): a real run's landmarks with their covariances, drawn in
map.png (the fused default, LOC-SMA refined, gives the model's covariances)."""

import warnings

import numpy as np
import pytest
from paths import SHARED_DATA

from lfmdr_gym.experiments.mrclam import map_mrclam_run

DATA = SHARED_DATA / "mrclam"


@pytest.mark.slow
@pytest.mark.skipif(not DATA.is_dir(), reason=f"MRCLAM data not found at {DATA}")
def test_a_real_run_carries_covariances(tmp_path):
    pytest.importorskip("matplotlib")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        res = map_mrclam_run(DATA / "MRCLAM_Dataset6", "range-bearing", out=tmp_path,
                             uncertainty=True)
    cov = res.covariances
    assert cov.shape == (len(res.subjects), 2, 2)
    anchors = np.isin(res.subjects, res.anchor_subjects)
    np.testing.assert_array_equal(cov[anchors], 0.0)
    spread = np.sqrt(np.trace(cov[~anchors], axis1=1, axis2=2))
    assert np.all((spread > 1e-4) & (spread < 0.5))  # millimetres to decimetres, finite
    assert (tmp_path / "map.png").stat().st_size > 0
