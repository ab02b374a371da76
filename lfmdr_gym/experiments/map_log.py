"""Mapping an observation log (``lfmdr map LOG --anchors A.csv``): a table of sightings
(:mod:`lfmdr_gym.histories.observation_table`) becomes a :class:`History`
(:func:`lfmdr_gym.histories.observations.observations_to_history`), is mapped like any history,
and its files are written as one set (:func:`lfmdr_gym.experiments.map_files.write_map_files`).
Ground truth, when given, only scores the map.
"""

from __future__ import annotations

import os
import warnings
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from lfmdr_gym.experiments.map_files import MapFiles, write_map_files
from lfmdr_gym.histories.history import History

__all__ = ["LOG_SUFFIXES", "LogMap", "check_anchor_table", "is_observation_log", "map_observation_log"]

LOG_SUFFIXES = (".csv", ".tsv", ".txt", ".parquet", ".pq")
"""File suffixes read as observation tables (anything else is a saved ``.npz`` history)."""


def is_observation_log(path: str | os.PathLike) -> bool:
    """Whether ``path`` names an observation table (CSV or Parquet) rather than a history."""
    return Path(path).suffix.lower() in LOG_SUFFIXES


@dataclass(frozen=True, eq=False)
class LogMap:
    """A map of an observation log.

    Attributes:
        map: the ``mappers.Map``.
        history: the History the log became.
        landmarks: landmark ids, one per row of ``map.positions``, as they are in the log.
        method, param: the method's label and its parameters as a label.
        files: what was written (None when ``out`` was None).
    """

    map: Any
    history: History
    landmarks: tuple[Any, ...]
    method: str
    param: str
    files: MapFiles | None

    @property
    def scores(self) -> dict[str, Any] | None:
        return None if self.files is None else self.files.scores


def check_anchor_table(anchors: Any, log_landmarks: Iterable[Any], log: str = "the log") -> None:
    """Anchors usable for a map of the log: at least 3, every one in the log, not collinear
    (coplanar in 3-D); else a ValueError naming the problem."""
    ids = anchors["landmark"].tolist()
    if len(ids) < 3:
        raise ValueError(f"{len(ids)} anchor(s) {ids}: a map needs at least 3 anchors "
                         "(landmarks of known position, not on one line)")
    known = set(log_landmarks)
    absent = [a for a in ids if a not in known]
    if absent:
        shown = sorted(known, key=str)
        raise ValueError(f"anchor(s) {absent} are not landmarks of {log} (its landmarks: "
                         f"{shown[:30]}{' ...' if len(shown) > 30 else ''}); an anchor must be "
                         "sighted to be fitted")
    axes = [a for a in ("x", "y", "z") if a in anchors.columns]
    points = anchors[axes].to_numpy(dtype=float)
    if len(axes) == 2:
        from mappers.core.align import check_not_collinear

        check_not_collinear(points, f"anchor positions of {ids}")
        return
    # 3-D: an affine map in space needs 4 anchors off one plane (np.linalg: rank of the spread)
    centred = points - points.mean(axis=0)
    s = np.linalg.svd(centred, compute_uv=False)
    if len(ids) < 4 or s[0] == 0 or s[-1] <= 1e-6 * s[0]:
        raise ValueError(f"anchor positions of {ids} are coplanar (singular values "
                         f"{np.round(s, 6).tolist()}): a 3-D map needs 4 anchors off one plane")


def map_observation_log(
    path: str | os.PathLike,
    anchors: str | os.PathLike,
    *,
    truth: str | os.PathLike | None = None,
    sensor: str | None = None,
    bin_width: float | None = None,
    method: str | None = None,
    params: Iterable[str] | Mapping[str, Any] | None = None,
    n_steps: int | None = None,
    out: str | os.PathLike | None = None,
    frame: str = "map",
    plot: bool = True,
) -> LogMap:
    """Map an observation table (CSV or Parquet) with the anchors of a landmark table.

    Args:
        path: the observation log (columns of :mod:`lfmdr_gym.histories.observation_table`).
        anchors: a table ``landmark, x, y`` (``z`` in 3-D) of landmarks of known position.
        truth: a table like ``anchors`` of true positions, for scores only; landmarks it lacks
            are not scored (``scores.json`` names them).
        sensor: which measurements to map (e.g. ``"bearing"``, ``"range-bearing"``); None =
            what the table has, as ``observations_to_history`` chooses.
        bin_width: seconds per time bin of a robot's frames (None: the converter's default).
        method, params: as for ``lfmdr map HISTORY.npz`` (None: the default for the history).
        n_steps: map only the first steps.
        out: the output folder (written as one set; on any error left as it was).
        frame: the anchors' frame, named in ``map.json`` / ``map.yaml``.
        plot: write ``map.png``.
    """
    from lfmdr_gym.experiments.mapping import method_and_params
    from lfmdr_gym.experiments.params import method_label, param_label
    from lfmdr_gym.experiments.scoring import map_history
    from lfmdr_gym.histories.observation_table import read_landmarks, read_observations
    from lfmdr_gym.histories.observations import observations_to_history

    table = read_observations(path)
    anchor_table = read_landmarks(anchors)
    check_anchor_table(anchor_table, table["landmark"].unique().tolist(), str(path))
    truth_table = read_landmarks(truth) if truth is not None else None
    history = observations_to_history(table, anchor_table, sensor=sensor, bin_width=bin_width)
    landmarks = tuple(history.meta["landmarks"])
    if n_steps is not None:
        history = history.head(n_steps)
    label, chosen = method_and_params(method, history, params)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the map's own warnings are in result.warnings
        result = map_history(history, label, chosen)
    files = None
    if out is not None:
        title = (f"{Path(path).name}, {method_label(label, chosen)}, "
                 f"{history.n_steps} steps")
        files = write_map_files(out, result, landmarks, history.anchor_ids,
                                history.anchor_positions, truth=truth_table, title=title,
                                frame=frame, plot=plot)
    return LogMap(result, history, landmarks, label, param_label(chosen), files)

