"""store_params: an estimator's __init__ stores its parameters as given, and nothing else."""

import pytest
from sklearn.base import BaseEstimator, clone

from mappers.core.estimator_params import store_params


class _Two(BaseEstimator):
    def __init__(self, *, a=1, b=(2, 3)) -> None:
        store_params(self, locals())


class _Three(_Two):
    def __init__(self, *, a=1, b=(2, 3), c=None) -> None:
        super().__init__(a=a, b=b)
        self.c = c


class _Late(BaseEstimator):
    def __init__(self, *, a=1) -> None:
        doubled = 2 * a  # noqa: F841 - a local that is no parameter
        store_params(self, locals())


def test_parameters_are_stored_unchanged_and_cloned():
    b = [4, 5]
    est = _Two(a=7, b=b)
    assert est.get_params() == {"a": 7, "b": [4, 5]}
    assert est.b is b
    assert clone(est).get_params() == {"a": 7, "b": [4, 5]}


def test_parent_init_through_super_stores_its_own():
    est = _Three(a=0, c="x")
    assert est.get_params() == {"a": 0, "b": (2, 3), "c": "x"}


def test_a_local_that_is_no_parameter_is_refused():
    with pytest.raises(TypeError, match=r"\['doubled'\] are not parameters"):
        _Late()
