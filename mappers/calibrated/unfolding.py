"""Classical metric unfolding of range histories (label ``"UNFOLD"``; the range default).

A range history holds, for every object i and step t, the distance ``r_it = |x_i - p_t|``
between the object and the robot. The squared distances are

    r_it^2 = |x_i|^2 - 2 x_i . p_t + |p_t|^2,

so once the row means (over steps) and column means (over objects) are removed, the matrix
``B = J_M R2 J_N`` (``R2`` the squared ranges, ``J`` the centring matrices) equals
``-2 (x_i - xbar) . (p_t - pbar)``: rank 2, whatever the robot's path. Its two leading left
singular vectors (scaled by the singular values) are therefore the objects' positions up to an
affine transformation of the plane, which the anchors' affine fit removes. This is Schönemann's
classical metric unfolding (Psychometrika 35, 1970), the two-set analogue of classical MDS; it is
a linear dimensionality reduction of the (squared) history matrix, like the paper's LPCA: no
pose, motion or measurement model goes in, and the step-side singular vectors (which mirror the
robot's path) are discarded.

Assumes: every object is ranged at every step (a zero range means "not sensed": use the masked
range methods of :mod:`mappers.masked.pair_maps` via ``build_map(..., mask=...)``), ranges are
centre-to-centre distances up to additive noise, and the robot's positions do not all lie on one
line (else ``B`` is rank 1 and the map is degenerate: a :class:`~mappers.paper.methods.MappingError`).

Its accuracy with and without range noise, against the paper's methods, is measured by
``python benchmarks/bench_mappers.py --sections range`` (figures in the README).
"""

from __future__ import annotations

from numbers import Integral

import numpy as np
from sklearn.base import BaseEstimator, TransformerMixin
from sklearn.utils._param_validation import Interval
from sklearn.utils.extmath import svd_flip
from sklearn.utils.validation import check_non_negative, validate_data

from mappers.core.errors import MappingError
from mappers.core.estimator_params import store_params

__all__ = ["ClassicalUnfolding"]


class ClassicalUnfolding(TransformerMixin, BaseEstimator):
    """Embed objects from their range histories by classical metric unfolding.

    Parameters:
        n_components: dimension of the embedding (2 for a map in the plane).
        zero_is_missing: treat a 0 range as "not sensed" (the convention of range sensors with a
            maximum range, such as LFMDR-Range-v0's ``max_range``) and refuse it, naming the
            masked methods; False (the estimator's default) takes 0 as a distance. The
            registered ``"UNFOLD"`` method uses True.

    ``fit_transform(X)`` takes X (M objects, N steps) of ranges >= 0 and returns the (M,
    n_components) embedding, an affine image of the objects' positions (fix it with anchors:
    :func:`mappers.fit_affine`, which ``build_map`` applies).

    Attributes:
        embedding_: the embedding; singular_values_: the leading singular values of the
        double-centred squared ranges (all of them, so the rank can be checked: exact ranges in
        the plane give exactly ``n_components`` non-zero ones); n_features_in_.
    """

    _parameter_constraints: dict = {
        "n_components": [Interval(Integral, 1, None, closed="left")],
        "zero_is_missing": ["boolean"],
    }

    def __init__(self, *, n_components: int = 2, zero_is_missing: bool = False) -> None:
        store_params(self, locals())

    def __sklearn_tags__(self):
        tags = super().__sklearn_tags__()
        tags.input_tags.positive_only = True  # ranges
        return tags

    def fit(self, X, y=None):
        self.fit_transform(X)
        return self

    def fit_transform(self, X, y=None):
        self._validate_params()
        X = validate_data(self, X, dtype=float, ensure_min_samples=2)
        k = self.n_components
        if X.shape[0] <= k or X.shape[1] <= k:
            raise ValueError(
                f"unfolding into {k} dimensions needs more than {k} objects and more than {k} "
                f"steps, got X of shape {X.shape}"
            )
        check_non_negative(X, "ClassicalUnfolding (ranges)")
        zeros = int(np.count_nonzero(X == 0))
        if zeros and self.zero_is_missing:
            raise ValueError(
                f"{zeros} range(s) are 0, i.e. not sensed (beyond max_range?): unfolding needs "
                "every object ranged at every step; map such histories with their mask "
                "(build_map(..., mask=X > 0) uses mappers.masked.pair_maps's range methods)"
            )
        R2 = X * X
        B = R2 - R2.mean(axis=0, keepdims=True) - R2.mean(axis=1, keepdims=True) + R2.mean()
        U, S, Vt = np.linalg.svd(B, full_matrices=False)
        U, Vt = svd_flip(U, Vt)  # deterministic signs
        if S[k - 1] <= 1e-12 * max(S[0], np.finfo(float).tiny):
            raise MappingError(
                f"UNFOLD: the double-centred squared ranges have rank {int(np.sum(S > 1e-12 * S[0]))} "
                f"< {k} (objects or robot positions all on one line?): no {k}-D map"
            )
        self.singular_values_ = S
        self.embedding_ = U[:, :k] * S[:k]
        return self.embedding_


def _unfold() -> ClassicalUnfolding:
    return ClassicalUnfolding(n_components=2, zero_is_missing=True)
