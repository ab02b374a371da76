"""A masked visibility history that is a log of sightings is not read as a view cone (issue 35)."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp

from mappers import build_map, default_method
from mappers.defaults import choose_for_history, is_sightings_log
from tests.mappers.viewpoints.test_view_cone import _camera

pytestmark = pytest.mark.usefixtures("one_blas_thread")

ANCHORS = np.arange(4)


def _view(n_steps: int = 250, m: int = 14, seed: int = 0):
    """Objects in a 2.5 m square seen through a 90-degree view cone from random poses:
    ``(objects, X, mask)``, observed = in the cone, visible = observed and nearer than 1 m."""
    P, _, X, mask = _camera(90.0, n_steps=n_steps, m=m, seed=seed, radius=1.0)
    return P, X, mask


def test_a_log_of_sightings_is_told_from_a_view_mask():
    _, X, mask = _view()
    sightings = mask & (X > 0.5)
    assert not is_sightings_log(X, mask)  # in view but not seen: observed zeros
    assert is_sightings_log(X, sightings)
    assert is_sightings_log(sp.csr_array(X), sp.csr_array(sightings))
    assert not is_sightings_log(sp.csr_array(X), sp.csr_array(mask))
    assert not is_sightings_log(X, None)  # a complete history
    assert not is_sightings_log(X, np.zeros_like(mask))  # nothing observed: nothing to say


def test_the_default_maps_a_log_of_sightings_without_view_ba_and_says_why():
    P, X, mask = _view()
    sightings = mask & (X > 0.5)
    assert default_method(X, sensor="visibility", mask=mask) == "VIEW-BA"
    assert default_method(X, sensor="visibility", mask=sightings) == "DROPOUT-BLEND"
    notes: list[str] = []
    assert choose_for_history(X, sightings, "visibility", notes=notes) == ("DROPOUT-BLEND", {})
    assert len(notes) == 1 and "log of what was seen" in notes[0]
    m = build_map(X, ANCHORS, P[ANCHORS], sensor="visibility", mask=sightings)
    assert m.method == "DROPOUT-BLEND" and np.all(np.isfinite(m.positions))
    assert any("log of what was seen" in w for w in m.warnings)
    # other sensors are not touched: a masked bearing history keeps its default
    assert choose_for_history(X, sightings, "range") == ("RANGE-QUANTILE", {})
