"""Storing an estimator's constructor parameters as given (scikit-learn's estimator contract).

scikit-learn's ``BaseEstimator`` reads the parameters back (``get_params``, ``clone``,
``set_params``) from attributes named as the ``__init__`` parameters, so an ``__init__`` must
store each of them unchanged and do nothing else: no validation, no defaults filled in (that
is ``fit``'s job). See "Developing scikit-learn estimators", section *Instantiation*:
https://scikit-learn.org/stable/developers/develop.html#instantiation
"""

from __future__ import annotations

import inspect
from collections.abc import Mapping

__all__ = ["store_params"]

# names Python itself puts in a method's locals(): the instance and, when the method calls
# super(), the class cell
_NOT_PARAMS = ("self", "__class__")


def store_params(estimator, given: Mapping[str, object]) -> None:
    """Store the ``__init__`` parameters held in ``given`` on ``estimator``, each unchanged.

    Parameters:
        estimator: the instance being constructed.
        given: the ``__init__``'s ``locals()``, called first thing in its body (so that it holds
            the parameters and nothing else): ``store_params(self, locals())``.

    Raises:
        TypeError: when ``given`` holds a name that is not a parameter of the estimator's
            ``__init__`` (a call placed after other code, or from another method).
    """
    params = {name: value for name, value in given.items() if name not in _NOT_PARAMS}
    # a parent's __init__ called through super() stores its own parameters: a subset
    taken = inspect.signature(type(estimator).__init__).parameters
    unknown = sorted(set(params) - set(taken))
    if unknown:
        raise TypeError(f"store_params({type(estimator).__name__}): {unknown} are not "
                        f"parameters of its __init__; call it first thing in __init__")
    for name, value in params.items():
        setattr(estimator, name, value)
