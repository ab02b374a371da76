"""Methods and their parameters as the experiments and the command line name them.

Labels resolve through the one registry (:func:`mappers.resolve_method`); parameters are written
``NAME=VALUE`` (the paper's names K, d and sigma^2 are accepted) and a parameter set is labelled
by one string (``"n_neighbors=5"``, ``"-"`` for none), the ``param`` column of the results.
"""

from __future__ import annotations

import inspect
import itertools
from collections.abc import Iterable, Mapping
from typing import Any

__all__ = [
    "PARAM_ALIASES",
    "default_params",
    "grid_params",
    "method_label",
    "param_label",
    "param_sort_key",
    "parse_params",
    "resolve_methods",
    "user_params",
]

PARAM_ALIASES: dict[str, str] = {"K": "n_neighbors", "k": "n_neighbors", "d": "degree",
                                 "sigma^2": "sigma2"}
"""The paper's names of parameters (K, d, sigma^2) -> the mappers' keyword names."""


def _methods() -> Mapping[str, Any]:
    from mappers import METHODS  # deferred: the registry loads scikit-learn

    return METHODS


def resolve_methods(names: Iterable[str] | None, sensor: str, masked: bool = False) -> tuple[str, ...]:
    """Canonical labels of ``names`` (case-insensitive), each checked to map ``sensor``'s histories
    (complete, or masked); for None, every method made for complete histories of ``sensor`` (the
    methods of the paper's tables and ours, not the masked-data methods nor the scalable forms
    for large M, ``MethodSpec.sparse``, which the protocol's M = 50 has no use for)."""
    from mappers import methods_for, resolve_method

    if names is None:
        return tuple(label for label in methods_for(sensor, masked)
                     if (masked or not _methods()[label].takes_masks)
                     and not _methods()[label].sparse)
    from mappers.catalog import implied_params

    out: list[str] = []
    for name in names:
        spec = resolve_method(str(name).strip(), sensor, masked)
        label, implied = spec.label, implied_params(spec)
        if implied:
            raise ValueError(f"method {name!r} is {label!r} with "
                             f"{', '.join(f'{k}={v!r}' for k, v in implied.items())}: the protocol "
                             "runs labels with their own defaults and grids; name the label")
        if label not in out:
            out.append(label)
    if not out:
        raise ValueError("methods must name at least one method")
    return tuple(out)


def param_label(params: Mapping[str, Any]) -> str:
    """The ``param`` column of a parameter set: ``"n_neighbors=5"``, ``"sigma2=0.5"``, or ``"-"``
    for none (names sorted, values as Python prints them, so :func:`parse_params` reads it back)."""
    if not params:
        return "-"
    return ",".join(f"{k}={params[k]}" for k in sorted(params))


def method_label(method: str, params: Mapping[str, Any] | str) -> str:
    """How a method and its parameters are shown to a reader: ``"ISOMAP (n_neighbors=7)"``, and
    just ``"CAL-SMA"`` when there is no parameter (``params`` a mapping, or a label of
    :func:`param_label`, whose ``"-"`` stands for none)."""
    label = params if isinstance(params, str) else param_label(params)
    return method if label in ("", "-") else f"{method} ({label})"


def number_or_text(text: str) -> Any:
    """``"5"`` -> 5, ``"0.5"`` -> 0.5, anything else stays text."""
    for kind in (int, float):
        try:
            return kind(text)
        except ValueError:
            pass
    return text


def parse_params(items: Iterable[str] | None) -> dict[str, Any]:
    """``["K=5", "sigma2=0.5"]`` (or ``"K=5,sigma2=0.5"`` items) -> ``{"K": 5, "sigma2": 0.5}``;
    values become int, else float, ``true``/``false`` (any case) bool (``sparse=true``), else
    stay text."""
    out: dict[str, Any] = {}
    for item in items or ():
        for part in str(item).split(","):
            if not part.strip() or part.strip() == "-":
                continue
            name, sep, text = part.partition("=")
            if not sep or not name.strip() or not text.strip():
                raise ValueError(f"parameters are given as NAME=VALUE, got {part!r}")
            value = text.strip()
            out[name.strip()] = {"true": True, "false": False}.get(value.lower(),
                                                                   number_or_text(value))
    return out


def user_params(method: str, items: Iterable[str] | Mapping[str, Any] | None) -> dict[str, Any]:
    """``method``'s defaults updated by user parameters (``["K=7"]`` or a dict; paper names
    such as K and d are accepted); unknown names raise ValueError naming the accepted ones."""
    given = dict(items) if isinstance(items, Mapping) else parse_params(items)
    given = {PARAM_ALIASES.get(k, k): v for k, v in given.items()}
    spec = _methods()[method]
    accepted = set(spec.parameters)  # register_method ensures it covers grid and defaults
    unknown = sorted(set(given) - accepted)
    if unknown:
        raise ValueError(f"unknown parameter(s) {unknown} for method {method!r}; "
                         f"it accepts {sorted(accepted) or 'none'}")
    return {**default_params(method), **given}


def grid_params(method: str) -> list[dict[str, Any]]:
    """Every parameter set of ``method``'s grid (one empty set when it has no parameter)."""
    grid = dict(_methods()[method].grid)
    names = sorted(grid)
    return [dict(zip(names, values, strict=True)) for values in itertools.product(*(grid[n] for n in names))]


def default_params(method: str) -> dict[str, Any]:
    """``method``'s default for each parameter its grid sweeps: the spec's default (the paper's
    optimum) or else the factory's own keyword default, so the label names a real value."""
    spec = _methods()[method]
    signature = inspect.signature(spec.load()).parameters
    out: dict[str, Any] = {}
    for name in sorted(spec.grid):
        if name in spec.defaults:
            out[name] = spec.defaults[name]
        elif name in signature and signature[name].default not in (inspect.Parameter.empty, None):
            out[name] = signature[name].default
    return out  # a method choosing its own value (default None) runs with no parameter: "-"


def param_sort_key(label: str) -> tuple[Any, ...]:
    """Sort ``"K=10"`` after ``"K=9"``: numbers compared as numbers."""
    out: list[Any] = []
    for name, value in parse_params([label]).items():
        out.append((name, (0, value, "") if isinstance(value, int | float) else (1, 0, str(value))))
    return tuple(out)
