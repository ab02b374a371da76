"""check_matrix: the one check of a history matrix's type and shape that build_map, fused
histories and the visibility adjustment share."""

import numpy as np
import pytest

from mappers.core.sensors import check_matrix


def test_a_matrix_comes_back_as_float_copied_or_not():
    X = np.ones((3, 2), dtype=int)
    out = check_matrix(X, "histories")
    assert out.dtype == float and out.shape == (3, 2)
    F = np.zeros((4, 1))
    assert check_matrix(F, "x", copy=False) is F
    assert check_matrix(F, "x") is not F


@pytest.mark.parametrize("value, match", [
    ([["a", "b"]] * 3, r"histories must be a numeric \(M, D\) array"),
    (np.zeros(5), r"histories must be a 2-D .* got shape \(5,\)"),
    (np.zeros((2, 4)), r"at least 3 objects .* got shape \(2, 4\)"),
    (np.zeros((3, 0)), r"1 column, got shape \(3, 0\)"),
])
def test_what_is_no_history_matrix_is_refused_by_name(value, match):
    with pytest.raises(ValueError, match=match):
        check_matrix(value, "histories")
