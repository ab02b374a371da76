"""The one Levenberg-Marquardt driver (engine.damped_step, issue 32) under each adjustment's
damping rule: which steps it accepts, how it raises and lowers the damping."""

import numpy as np
import pytest

from mappers.spatial.adjustment import DAMPING as SPATIAL
from mappers.viewpoints.bearing import DAMPING as BEARING
from mappers.viewpoints.engine import Damping, damped_step
from mappers.viewpoints.range_bearing import DAMPING as RANGE_BEARING
from mappers.viewpoints.view_cone import DAMPING as VIEW_CONE


def _costs(*values):
    """A try_step whose k-th call costs values[k]; records the dampings it was called with."""
    calls = []

    def try_step(lam):
        calls.append(lam)
        return len(calls), values[len(calls) - 1]

    return try_step, calls


def test_a_step_is_retried_with_more_damping_until_the_cost_falls():
    try_step, calls = _costs(5.0, np.nan, 3.0)
    state, cost, lam, ok = damped_step(try_step, 4.0, 1e-4, BEARING)
    assert ok and state == 3 and cost == 3.0
    np.testing.assert_allclose(calls, [1e-4, 1e-3, 1e-2])
    assert lam == pytest.approx(1e-3)  # lowered 10x after the accepted try


def test_equal_cost_accepted_only_where_the_rule_says():
    for rule, accepted in ((BEARING, True), (RANGE_BEARING, True), (SPATIAL, False), (VIEW_CONE, False)):
        try_step, calls = _costs(*([2.0] * 20))
        *_, ok = damped_step(try_step, 2.0, 1e-3, rule)
        assert ok is accepted


def test_no_step_falls_the_damping_is_raised_by_the_rule():
    try_step, calls = _costs(*([9.0] * 100))
    state, cost, lam, ok = damped_step(try_step, 1.0, 1e-4, VIEW_CONE)
    assert not ok and state is None and cost == 1.0
    assert len(calls) == 8 and lam == pytest.approx(1e-4 * 5.0**8)
    try_step, calls = _costs(*([9.0] * 100))
    *_, lam, ok = damped_step(try_step, 1.0, 1e-3, SPATIAL)
    assert not ok and len(calls) == 11 and lam >= 1e8  # up to the ceiling, no count
    try_step, calls = _costs(*([np.inf] * 100))
    *_, ok = damped_step(try_step, np.inf, 1e-3, BEARING)
    assert not ok and len(calls) == 12  # an infinite cost is never accepted


def test_the_floor_bounds_the_lowered_damping():
    try_step, _ = _costs(0.5)
    *_, lam, ok = damped_step(try_step, 1.0, 2e-6, VIEW_CONE)
    assert ok and lam == 1e-6


@pytest.mark.parametrize("bad", [{"up": 1.0}, {"down": 0.5}, {"floor": -1.0}, {"tries": 0}])
def test_a_bad_rule_is_refused(bad):
    with pytest.raises(ValueError, match="damping rule"):
        Damping(**bad)
