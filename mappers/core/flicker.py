"""What a visibility history reveals about dropouts: the flicker rate.

A robot that walks smoothly sees an object come into view and go out of it in runs of steps:
visible at ``t - 1`` and at ``t + 1`` but not at ``t`` ("a flicker") is rare with perfect
sensing (an object hidden for one step behind another, or at the edge of sight). A camera that
misses each visible object with probability ``p`` independently turns such a step into a 0 with
probability ``p``, so the share of flickers among the steps whose neighbours are both visible
estimates ``p``. The mapper is never told the miss rate; this statistic reads it from the
timeline of the history. The rates measured with and without misses:
``docs/imperfect-sensing.md#flicker-rate``.

*Assumes*: consecutive steps (by the timeline: the same robot, consecutive ticks) are close
viewpoints, and misses are independent. The first is checked from the data too
(:func:`persistence`): histories from unordered viewpoints (random poses, shuffled logs) flicker
as often as they see anything, and are not read this way.
"""

from __future__ import annotations

import numpy as np

from mappers.core.sensors import check_timeline

__all__ = ["FLICKER_THRESHOLD", "MIN_PERSISTENCE", "flicker_rate", "persistence", "step_runs"]

FLICKER_THRESHOLD = 0.15  # between perfect sensing and misses: docs/imperfect-sensing.md#flicker-rate
"""Flicker rate above which ``build_map`` treats a complete visibility history as one with
dropouts (the ``dropouts`` column of :data:`mappers.defaults.DEFAULTS`)."""


MIN_PERSISTENCE = 2.0  # between walks and random viewpoints: docs/imperfect-sensing.md#flicker-rate
"""Smallest :func:`persistence` at which the flicker rate is read (misses scale both sides of
its ratio alike, so it does not depend on them)."""


def step_runs(n_steps: int, timeline=None) -> list[np.ndarray]:
    """The steps in runs of consecutive ticks of one robot (arrays of column indices, in tick
    order); one run ``0..n_steps-1`` without a timeline (one robot, one step per tick)."""
    tl = check_timeline(timeline, n_steps)
    if tl is None:
        return [np.arange(n_steps)]
    order = np.lexsort((tl[:, 1], tl[:, 0]))
    robot, tick = tl[order, 0], tl[order, 1]
    breaks = np.flatnonzero((np.diff(robot) != 0) | (np.diff(tick) != 1)) + 1
    return [run for run in np.split(order, breaks) if run.size]


def _visible_runs(X, timeline):
    """``(V, runs)``: the (M, N) visible flags of ``X`` and each run of :func:`step_runs` of at
    least 3 steps as its (M, steps) block of ``V``."""
    V = np.asarray(X) != 0
    if V.ndim != 2:
        raise ValueError(f"X must be a 2-D (objects, steps) visibility history, got shape {V.shape}")
    return V, [V[:, run] for run in step_runs(V.shape[1], timeline) if run.size >= 3]


def flicker_rate(X, timeline=None) -> float:
    """Share of the (object, step) entries visible at the step before and after (in the same
    run of :func:`step_runs`) that read not visible: an estimate of the miss rate (module
    docstring). ``X``: (M, N) visibility history (non-zero = visible). NaN when no entry has
    both neighbours visible."""
    _, runs = _visible_runs(X, timeline)
    both = flicks = 0
    for R in runs:
        sides = R[:, :-2] & R[:, 2:]
        both += int(sides.sum())
        flicks += int((sides & ~R[:, 1:-1]).sum())
    return flicks / both if both else float("nan")


def persistence(X, timeline=None) -> float:
    """How much more often an object visible at a step is visible two steps later (in the same
    run of :func:`step_runs`) than at a step taken at random: ``P(x[t+2] | x[t]) / P(x)``.
    About 1 for unordered viewpoints, several times that for a walk; dropouts scale both sides
    alike. NaN when nothing is visible."""
    V, runs = _visible_runs(X, timeline)
    base = V.mean() if V.size else 0.0
    first = both = 0
    for R in runs:
        first += int(R[:, :-2].sum())
        both += int((R[:, :-2] & R[:, 2:]).sum())
    return both / first / base if first and base else float("nan")
