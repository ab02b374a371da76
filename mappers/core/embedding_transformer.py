"""The ``fit_transform`` of a mapper whose ``fit`` stores its map as ``embedding_``.

scikit-learn's ``TransformerMixin.fit_transform`` calls ``fit(X, y, **fit_params).transform(X)``;
a mapper places the objects of the history it was fitted on and has no ``transform`` of new
histories, so its ``fit_transform`` returns the map ``fit`` stored. See "Developing
scikit-learn estimators", section *Estimated attributes*:
https://scikit-learn.org/stable/developers/develop.html#estimated-attributes
"""

from __future__ import annotations

import numpy as np
from sklearn.base import TransformerMixin

__all__ = ["EmbeddingTransformer"]


class EmbeddingTransformer(TransformerMixin):
    """Mixin (before ``BaseEstimator``) for a mapper whose ``fit`` returns ``self`` with its map
    in ``embedding_``."""

    def fit_transform(self, X, y=None, **inputs) -> np.ndarray:
        """Fit on ``X`` with the mapper's keyword ``inputs`` (e.g. ``anchor_ids``,
        ``anchor_positions``, ``mask``) and return ``embedding_``."""
        return self.fit(X, y, **inputs).embedding_
