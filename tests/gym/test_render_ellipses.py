"""The 95 % ellipses of Map.covariances drawn on maps (lfmdr_gym.render)."""

import numpy as np
import pytest
from scipy.stats import chi2

from lfmdr_gym.render import ELLIPSE, draw_ellipses, draw_map, ellipse_outlines


def test_outlines_lie_on_the_95_percent_contour():
    pos = np.array([[0.0, 0.0], [1.0, -1.0], [0.5, 0.5]])
    cov = np.array([[[0.04, 0.01], [0.01, 0.02]], np.zeros((2, 2)), np.full((2, 2), np.nan)])
    out = ellipse_outlines(pos, cov)
    assert out.shape == (3, 49, 2)
    e = out[0] - pos[0]
    q = np.einsum("ni,ij,nj->n", e, np.linalg.inv(cov[0]), e)
    np.testing.assert_allclose(q, chi2.ppf(0.95, 2), rtol=1e-9)
    assert np.isnan(out[1]).all() and np.isnan(out[2]).all()  # an anchor, an unmapped object


def test_outlines_reject_mismatched_shapes():
    with pytest.raises(ValueError, match="covariances must have shape"):
        ellipse_outlines(np.zeros((3, 2)), np.zeros((2, 2, 2)))


def test_draw_map_draws_the_ellipses():
    est = np.array([[0.0, 0.0], [0.3, 0.2], [-0.4, 0.1]])
    cov = np.tile(np.eye(2) * 0.01, (3, 1, 1))
    plain = draw_map(arena_half=1.0, estimates=est, object_radius=0.02)
    drawn = draw_map(arena_half=1.0, estimates=est, object_radius=0.02, covariances=cov)
    ellipse_px = np.all(drawn == ELLIPSE, axis=2)
    assert ellipse_px.sum() > 100 and not np.all(plain == ELLIPSE, axis=2).any()


def test_draw_ellipses_on_matplotlib_axes():
    matplotlib = pytest.importorskip("matplotlib")
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots()
    cov = np.array([np.eye(2) * 0.01, np.zeros((2, 2))])
    assert draw_ellipses(ax, np.zeros((2, 2)), cov) == 1
    assert len(ax.lines) == 1
    plt.close(fig)
