"""Env keywords for the experiments: ``NAME=VALUE`` settings such as ``fov_deg=90`` checked
against the environment, so that runs with imperfect sensing (:mod:`lfmdr_gym.sim.sensing_limits`) can be
collected, recorded in a run's settings and resumed only with the same settings."""

from __future__ import annotations

import inspect
from collections.abc import Iterable, Mapping
from typing import Any

from lfmdr_gym.experiments.params import number_or_text

__all__ = ["check_env_kwargs", "parse_env_kwargs"]

# Keywords the experiments set themselves (the sensor comes from --sensor or the env id).
_RESERVED = ("sensor",)


def _value(text: str) -> Any:
    """``"90"`` -> 90, ``"1.5"`` -> 1.5, ``"true"``/``"false"`` -> bool, ``"none"`` -> None,
    anything else stays text (e.g. ``anchors=random``)."""
    low = text.lower()
    if low in ("true", "false"):
        return low == "true"
    if low == "none":
        return None
    return number_or_text(text)


def parse_env_kwargs(items: Iterable[str] | None) -> dict[str, Any]:
    """``["fov_deg=90", "max_range=1.5"]`` -> ``{"fov_deg": 90, "max_range": 1.5}`` (values
    parsed as numbers, booleans or None where they read as one); a keyword given twice or an
    item without ``=`` is a ValueError."""
    out: dict[str, Any] = {}
    for item in items or ():
        name, sep, text = str(item).partition("=")
        name, text = name.strip(), text.strip()
        if not sep or not name or not text:
            raise ValueError(f"env keywords are given as NAME=VALUE, got {item!r}")
        if name in out:
            raise ValueError(f"env keyword {name!r} is given twice")
        out[name] = _value(text)
    return out


def check_env_kwargs(sensor: str, kwargs: Mapping[str, Any] | None) -> tuple[dict[str, Any], bool]:
    """``kwargs`` checked against the environment, and whether its histories are masked.

    An unknown keyword, or one the experiments set themselves (``sensor``), is a ValueError
    naming it; values are checked by building the environment (its own ValueError names the
    keyword). The histories are masked when the env reports ``"observed"``, i.e. a sensing limit
    is on.
    """
    from lfmdr_gym.env import LFMDREnv

    kwargs = dict(kwargs or {})
    if not kwargs:
        return kwargs, False  # the registered env as it is: perfect sensing
    accepted = [n for n in inspect.signature(LFMDREnv).parameters if n not in _RESERVED]
    for name in kwargs:
        if name in _RESERVED:
            raise ValueError(f"env keyword {name!r} is set by the experiment, not by an env keyword")
        if name not in accepted:
            raise ValueError(f"unknown env keyword {name!r}; the environment accepts {accepted}")
    env = LFMDREnv(sensor, **kwargs)
    try:
        masked = "observed" in env.observation_space.spaces
    finally:
        env.close()
    return kwargs, masked
