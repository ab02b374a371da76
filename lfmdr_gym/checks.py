"""Argument checks shared by the world, the policies and the recorders: a bad value raises
ValueError naming the argument."""

from __future__ import annotations

import math
import numbers
from typing import Any

__all__ = ["check_int", "check_real"]


def check_real(name: str, value: Any, *, low: float = -math.inf, low_open: bool = False,
               high: float = math.inf, high_open: bool = False) -> float:
    """``value`` as a finite float within the bounds, else ValueError naming ``name``."""
    if isinstance(value, bool) or not isinstance(value, numbers.Real) or not math.isfinite(value):
        raise ValueError(f"{name} must be a finite number, got {value!r}")
    v = float(value)
    if (v < low or (low_open and v == low)) or (v > high or (high_open and v == high)):
        if high == math.inf:  # one-sided: "> 0" rather than "(0, inf]"
            bound = (">" if low_open else ">=") + f" {low:g}"
        elif low == -math.inf:
            bound = ("<" if high_open else "<=") + f" {high:g}"
        else:
            lo = ("(" if low_open else "[") + f"{low:g}"
            hi = f"{high:g}" + (")" if high_open else "]")
            bound = f"in {lo}, {hi}"
        raise ValueError(f"{name} must be {bound}, got {value!r}")
    return v


def check_int(name: str, value: Any, *, low: int) -> int:
    """``value`` as an int >= ``low``, else ValueError naming ``name``."""
    if isinstance(value, bool) or not isinstance(value, numbers.Integral):
        raise ValueError(f"{name} must be an integer, got {value!r}")
    if value < low:
        raise ValueError(f"{name} must be >= {low}, got {value!r}")
    return int(value)
