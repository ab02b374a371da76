"""Mapping a real MRCLAM run and scoring it against motion capture (``lfmdr mrclam``).

The run goes through its observation table, as ``lfmdr convert mrclam`` writes it and ``lfmdr
map`` reads it (:mod:`lfmdr_gym.datasets.mrclam_table`,
:func:`lfmdr_gym.histories.observations.observations_to_history`: the History the loader,
:mod:`lfmdr_gym.datasets.mrclam`, gives); here it is mapped with any
registered method that maps its histories (:func:`mappers.build_map`), by default the one
:func:`mappers.defaults.choose_method` names for a logged run (``logged=True``: the ``logged``
column of :data:`mappers.defaults.DEFAULTS`), scored over the non-anchor landmarks, and written
as ``map.csv`` and ``map.png``. Ground truth places the anchors and scores; nothing else of it
reaches the mapper.
"""

from __future__ import annotations

import dataclasses
import math
import os
import warnings
from collections.abc import Sequence
from dataclasses import dataclass
from fractions import Fraction
from pathlib import Path
from typing import Any

import numpy as np

from lfmdr_gym.atomic import atomic_write_text
from lfmdr_gym.datasets.mrclam import (
    DEFAULT_BIN_WIDTH,
    ROBOT_SUBJECTS,
    MRCLAMDataWarning,
    MRCLAMReport,
    read_run,
    run_meta,
)
from lfmdr_gym.datasets.mrclam_table import mrclam_anchors, mrclam_landmarks, mrclam_observations
from lfmdr_gym.experiments.object_names import landmark_notes
from lfmdr_gym.histories.history import History
from lfmdr_gym.histories.observations import observations_to_history
from mappers.core.sensors import COLUMNS_PER_STEP, check_sensor_set, sensor_name, sensors_of

__all__ = ["ENSEMBLE_BIN_WIDTHS", "FUSED_BIN_WIDTH", "METHOD_ALIASES", "MRCLAMMap", "map_mrclam_run"]

_ENSEMBLE = "COVIS-ENSEMBLE"
FUSED_BIN_WIDTH: dict[str, float] = {"range-bearing": DEFAULT_BIN_WIDTH["range-bearing"]}
"""Bin width [s] of fused runs when none is given: the law of cosines needs both readings from
one viewpoint, so bins stay near the camera period (chosen leave-one-run-out,
``benchmarks/bench_mrclam.py``)."""

ENSEMBLE_BIN_WIDTHS: tuple[float, ...] = (1.0, 1.5, 2.0, 3.0, 4.0, 5.0)
"""Bin widths [s] of the COVIS-ENSEMBLE's members on real runs (``bin_widths=`` overrides); one
``bin_width`` asked for with the default method: one member at that width (``min_co`` 3)."""

METHOD_ALIASES: dict[str, str] = {"naive": "SMA(UNWGT)"}
"""Older names: ``naive`` is the paper's pipeline on the zero-filled history (``zero_fill``)."""


@dataclass(frozen=True, eq=False)
class MRCLAMMap:
    """A map of one MRCLAM run and its scores against motion capture.

    Attributes:
        run, sensor, method, params: what was mapped and how.
        subjects: (M,) landmark subject numbers, one per row of ``positions``.
        positions: (M, 2) estimates in the ground-truth frame (anchors included; NaN = unmapped).
        truth: (M, 2) ground truth (after ``groundtruth_fixes``).
        anchor_subjects: subjects used as anchors.
        mpe: mean position error [m] over the mapped non-anchor landmarks.
        moe: mean orientation error [%] over the mapped non-anchor landmarks.
        centroid_mpe: MPE of placing every non-anchor landmark at the anchors' centroid.
        warnings: data and mapping warnings (also issued as :class:`MRCLAMDataWarning`); the
            landmarks they name are subject numbers (a mapper's object rows are translated).
        report: the loader's filtering report.
        history_meta: ``History.meta`` of the binned history.
        csv_path, png_path: files written (None when ``out`` is None).
        covariances: (M, 2, 2) each landmark's position covariance in the ground-truth frame
            (``Map.covariances``; zero for anchors, NaN for unmapped), None unless asked for
            (``uncertainty=``).
    """

    run: str
    sensor: str
    method: str
    params: dict[str, Any]
    subjects: np.ndarray
    positions: np.ndarray
    truth: np.ndarray
    anchor_subjects: tuple[int, ...]
    mpe: float
    moe: float
    centroid_mpe: float
    warnings: tuple[str, ...]
    report: MRCLAMReport
    history_meta: dict[str, Any]
    csv_path: Path | None = None
    png_path: Path | None = None
    covariances: np.ndarray | None = None

    @property
    def mode(self) -> str:
        """The older name of :attr:`sensor`."""
        return self.sensor


def _tick(widths: Sequence[float]) -> float:
    """The coarsest bin width [s] every width is a whole multiple of (their greatest common
    divisor, from their decimal values): the ensemble's members are unions of such bins."""
    fr = [Fraction(w).limit_denominator(1000) for w in widths]
    num = math.gcd(*(f.numerator * (math.lcm(*(g.denominator for g in fr)) // f.denominator)
                     for f in fr))
    return num / math.lcm(*(f.denominator for f in fr))


def _plan(sensor: str, method: str | None, bin_width: float | None, params: dict[str, Any],
          zero_fill: bool):
    """(method label, bin width of the history, the method's parameters, whether the label was
    ``naive``: SMA(UNWGT) on the zero-filled history)."""
    from mappers import resolve_method
    from mappers.catalog import implied_params
    from mappers.defaults import choose_method

    naive = False
    if bin_width is None and sensor in FUSED_BIN_WIDTH:
        bin_width = FUSED_BIN_WIDTH[sensor]
    if method in METHOD_ALIASES:
        method, naive = METHOD_ALIASES[method], True
    if method is None:  # the default for a logged run, with one member at a bin width asked for
        method, chosen = choose_method(sensor, masked=True, logged=True)
        params = {**chosen, **params}
        if method == _ENSEMBLE and bin_width is not None:
            params = {"bin_widths": (bin_width,), "min_co": 3, **params}
            bin_width = None
    else:  # an old label: its new one (with a FutureWarning) or why it is no longer one
        spec = resolve_method(method, sensor, masked=not (zero_fill or naive))
        method, params = spec.label, {**implied_params(spec), **params}
    if method != _ENSEMBLE:
        return method, bin_width, params, naive
    if bin_width is not None:
        raise ValueError(f"method {_ENSEMBLE!r} bins the run at several widths (bin_widths=...); "
                         "bin_width must be None")
    widths = tuple(float(w) for w in np.atleast_1d(params.pop("bin_widths", ENSEMBLE_BIN_WIDTHS)))
    if not widths or min(widths) <= 0:
        raise ValueError(f"bin_widths must be positive numbers of seconds, got {widths}")
    tick = _tick(widths)
    return method, tick, {"windows": tuple(round(w / tick) for w in widths), **params}, naive


def _load(run_dir, key, robots, bin_width, anchors, groundtruth_fixes):
    """The run's History (a fused set: a dict sensor -> History, its parts, binned alike) and
    the loader's report, through the run's observation table: what ``lfmdr convert mrclam``
    writes (:func:`~lfmdr_gym.datasets.mrclam_table.mrclam_observations`, its anchors and ground
    truth) and ``lfmdr map`` reads
    (:func:`~lfmdr_gym.histories.observations.observations_to_history`), which gives the History
    :func:`~lfmdr_gym.datasets.mrclam.load_mrclam` gives; the loader's meta and warnings added."""
    name = sensor_name(key)
    if bin_width is None and name not in DEFAULT_BIN_WIDTH:
        raise ValueError(f"no default bin width for {name!r}: give bin_width (seconds)")
    bin_width = DEFAULT_BIN_WIDTH[name] if bin_width is None else bin_width
    run = read_run(run_dir, robots, groundtruth_fixes=groundtruth_fixes)
    history = observations_to_history(mrclam_observations(run), mrclam_anchors(run, anchors),
                                      truth=mrclam_landmarks(run), sensor=name,
                                      bin_width=bin_width)
    # co-observation from the sightings: the mask of a sensor that keeps every one of them
    first = next(s for s in ("range", "visibility", "bearing") if s in sensors_of(name))
    part = history.parts[first] if history.fused else history
    seen = np.asarray(part.mask)[:, :: COLUMNS_PER_STEP[first]]
    meta = run_meta(run, name, history.anchor_ids, seen)
    meta.update(bin_width=float(bin_width), n_bins=history.n_steps, drop_empty_bins=True,
                bins_per_robot={str(r): int(np.sum(history.timeline[:, 0] == k))
                                for k, r in enumerate(run.report.robots)},
                observed_fraction=[round(float(f), 5) for f in seen.mean(axis=1)])
    history = history.replace(meta=meta)
    report = MRCLAMReport.from_meta(meta)
    # a fused set is mapped from its parts (sensor -> History), as it always has been
    return (history if isinstance(key, str) else dict(history.parts)), report


def _scores(positions: np.ndarray, history: History) -> tuple[float, float, float]:
    """MPE and MOE over the mapped non-anchor landmarks, and the anchors' centroid baseline."""
    from mappers import mean_orientation_error, mean_position_error

    anchors = set(history.anchor_ids.tolist())
    truth = history.object_positions
    scored = [i for i in range(len(truth))
              if i not in anchors and np.all(np.isfinite(positions[i]))]
    exclude = [i for i in range(len(truth)) if i not in scored]
    mpe = mean_position_error(positions, truth, exclude=exclude) if scored else math.nan
    moe = mean_orientation_error(positions, truth, exclude=exclude) if len(scored) >= 3 else math.nan
    centroid = np.repeat(truth[history.anchor_ids].mean(axis=0)[None], len(truth), axis=0)
    return float(mpe), float(moe), mean_position_error(centroid, truth, exclude=sorted(anchors))


def _reported_params(method: str, params: dict[str, Any], tick: float | None) -> dict[str, Any]:
    """The parameters as the user gives them (an ensemble's windows as bin widths in seconds)."""
    from mappers import METHODS

    used = METHODS[method].resolved_params(params)
    if method == _ENSEMBLE:
        used = {"bin_widths": [w * tick for w in used.pop("windows")], **used,
                "min_co": [int(m) for m in np.atleast_1d(used["min_co"])]}
        used["power"] = 0.5 if used["power"] is None else used["power"]
        used.pop("max_iter", None)
    return used


def map_mrclam_run(
    run_dir: str | os.PathLike,
    sensor: str = "visibility",
    robots: Sequence[int] = ROBOT_SUBJECTS,
    method: str | None = None,
    anchors: Sequence[int] | None = None,
    out: str | os.PathLike | None = None,
    bin_width: float | None = None,
    *,
    groundtruth_fixes: str = "known",
    plot: bool = True,
    zero_fill: bool = False,
    mode: str | None = None,
    uncertainty: bool | str = False,
    **params: Any,
) -> MRCLAMMap:
    """Map one MRCLAM run from one sensor and score it against motion capture.

    The parameters map 1:1 onto ``lfmdr mrclam RUN_DIR --sensor SENSOR --robots 1,2,3,4,5
    --method M --anchors S1,S2,S3,S4 --out DIR --bin-width SECONDS --zero-fill``.

    Args:
        run_dir: the run's directory.
        sensor: ``"visibility"``, ``"bearing"``, ``"range"`` or ``"range-bearing"`` (both
            measurements of every sighting, fused; ``mode=`` is the older name).
        robots: robot subject numbers whose logs to use.
        method: any registered method that maps the run's (masked) histories, e.g.
            ``"COVIS-ENSEMBLE"`` (``bin_widths`` [s] and ``min_co`` sequences, ``member``,
            ``power``), ``"RANGE-QUANTILE"``, ``"LOC-SMA"``; a method for complete histories
            with ``zero_fill``; ``"naive"`` = ``"SMA(UNWGT)"`` with ``zero_fill``; None =
            the default for a logged run of the sensor
            (``mappers.defaults.choose_method(sensor, masked=True, logged=True)``:
            ``COVIS-ENSEMBLE`` for visibility and bearing, ``RANGE-QUANTILE`` for range,
            ``LOC-SMA`` for range-bearing).
        anchors: anchor landmark subject numbers; None = the 4 nearest the bounding-box corners.
        out: directory for ``map.csv`` (subject, x, y of every landmark, anchors included, in
            the ground-truth frame; written atomically) and ``map.png``; None writes nothing.
        bin_width: seconds per bin; None = the loader's default for the sensor (for fused
            sensors :data:`FUSED_BIN_WIDTH`); must be None for
            ``COVIS-ENSEMBLE``; given with ``method=None`` for visibility or bearing, the
            ensemble of one member (``bin_widths=(bin_width,)``, ``min_co=3``) maps the run
            binned at that one width.
        groundtruth_fixes: ``"known"`` / ``"detect"`` / ``"none"`` (see ``read_run``).
        plot: write ``map.png`` (needs matplotlib) when ``out`` is given.
        zero_fill: map the history with its unobserved entries as zeros and no mask (the paper's
            pipeline on logged data), so methods for complete histories apply.
        uncertainty: each landmark's covariance (``build_map(uncertainty=...)``, kept in
            ``MRCLAMMap.covariances`` and drawn as 95 % ellipses in ``map.png``).
        **params: the method's parameters (e.g. ``quantile=0.95``, ``min_co=5``).
    """
    from mappers import build_map

    key = check_sensor_set(mode if mode is not None else sensor)
    sensor = sensor_name(key)
    method, bin_width, params, alias_fill = _plan(sensor, method, bin_width, dict(params),
                                                  zero_fill)
    histories, report = _load(run_dir, key, robots, bin_width, anchors, groundtruth_fixes)
    if zero_fill or alias_fill:
        histories = (histories.replace(mask=None) if isinstance(key, str) else
                     {s: h.replace(mask=None) for s, h in histories.items()})
    history = histories if isinstance(key, str) else next(iter(histories.values()))
    result = build_map(histories, history.anchor_ids, history.anchor_positions, method,
                       uncertainty=uncertainty, **params)
    run = history.meta["run"]
    subjects = np.asarray(history.meta["subjects"], dtype=np.int64)
    msgs = [*report.warnings, *_warn_map(result, histories, run, sensor, subjects)]
    mpe, moe, centroid_mpe = _scores(result.positions, history)
    label = "naive" if alias_fill else result.method
    outcome = MRCLAMMap(
        run=str(run), sensor=sensor, method=label,
        params={} if alias_fill else _reported_params(result.method, params, bin_width),
        subjects=subjects, positions=result.positions, truth=history.object_positions,
        anchor_subjects=tuple(int(s) for s in subjects[history.anchor_ids]), mpe=mpe, moe=moe,
        centroid_mpe=centroid_mpe, warnings=tuple(msgs), report=report,
        history_meta={**history.meta, "sensor": sensor}, covariances=result.covariances,
    )
    return outcome if out is None else _write(outcome, Path(out), plot)


def _warn_map(result: Any, histories: Any, run: Any, sensor: str,
              subjects: np.ndarray) -> list[str]:
    """The map's warnings and unmapped subjects, as messages naming the run, each also warned
    (as a ``MRCLAMDataWarning`` at the caller of :func:`map_mrclam_run`)."""
    msgs: list[str] = []
    for w in landmark_notes(result.warnings, subjects, histories):  # subjects, not rows
        msgs.append(f"{run} ({sensor}, {result.method}): {w}")
        warnings.warn(msgs[-1], MRCLAMDataWarning, stacklevel=3)
    if result.unmapped:
        msgs.append(f"{run} ({sensor}): subject(s) {subjects[list(result.unmapped)].tolist()} are "
                    "unmapped (empty in map.csv) and not scored")
        warnings.warn(msgs[-1], MRCLAMDataWarning, stacklevel=3)
    return msgs


def _write(result: MRCLAMMap, out: Path, plot: bool) -> MRCLAMMap:
    lines = ["subject,x,y"]
    for s, (x, y) in zip(result.subjects, result.positions, strict=True):
        lines.append(f"{int(s)},{'' if np.isnan(x) else f'{x:.6f}'},{'' if np.isnan(y) else f'{y:.6f}'}")
    csv_path = out / "map.csv"
    atomic_write_text(csv_path, "\n".join(lines) + "\n")
    png_path = None
    if plot:
        from lfmdr_gym.experiments.figures import plot_estimate

        png_path = out / "map.png"
        anchors = np.flatnonzero(np.isin(result.subjects, result.anchor_subjects))
        title = (f"{result.run} {result.sensor} ({result.method}): MPE {result.mpe:.2f} m, "
                 f"MOE {result.moe:.1f} %")
        plot_estimate(result.positions, result.truth, anchors, png_path, title=title,
                      labels=result.subjects, notes=result.warnings,
                      covariances=result.covariances)
    return dataclasses.replace(result, csv_path=csv_path, png_path=png_path)
