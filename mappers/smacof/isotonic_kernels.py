"""The compiled loop of :func:`mappers.smacof.isotonic.isotonic_fit`: tied inputs merged.

One pass over the sorted pairs, summing each run of equal inputs in order, exactly as
scikit-learn's ``sklearn._isotonic._make_unique`` does (so that the disparities are the same to
the last bit); numba compiles it on first use (:mod:`mappers.core.jit`).
"""

from __future__ import annotations

import numpy as np

from mappers.core.jit import compiled_on_first_use

__all__ = ["merge_ties"]  # noqa: F822 - bound by __getattr__

__getattr__ = compiled_on_first_use(globals(), __all__)


def _merge_ties(x, y, w, eps):  # pragma: no cover - compiled
    """For ``x`` sorted (ascending), the runs of inputs closer than ``eps`` to the run's first
    merged into one: ``(x of the run's first, weighted mean of y, summed weight)`` per run, each
    sum taken in order."""
    n = x.size
    x_out = np.empty(n)
    y_out = np.empty(n)
    w_out = np.empty(n)
    current_x = x[0]
    current_y = 0.0
    current_w = 0.0
    i = 0
    for j in range(n):
        if x[j] - current_x >= eps:
            x_out[i] = current_x
            w_out[i] = current_w
            y_out[i] = current_y / current_w
            i += 1
            current_x = x[j]
            current_w = w[j]
            current_y = y[j] * w[j]
        else:
            current_w += w[j]
            current_y += y[j] * w[j]
    x_out[i] = current_x
    w_out[i] = current_w
    y_out[i] = current_y / current_w
    return x_out[:i + 1], y_out[:i + 1], w_out[:i + 1]
