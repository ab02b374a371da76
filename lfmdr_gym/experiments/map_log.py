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

from lfmdr_gym.experiments.map_files import MapFiles, write_map_files
from lfmdr_gym.experiments.object_names import landmark_notes
from lfmdr_gym.histories.history import History

__all__ = ["LOG_SUFFIXES", "LogMap", "is_observation_log", "map_observation_log"]

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
        notes: the map's warnings with the objects they name as landmark ids, not rows
            (:func:`lfmdr_gym.experiments.object_names.landmark_notes`); ``map.warnings``
            count rows.
    """

    map: Any
    history: History
    landmarks: tuple[Any, ...]
    method: str
    param: str
    files: MapFiles | None
    notes: tuple[str, ...] = ()

    @property
    def scores(self) -> dict[str, Any] | None:
        return None if self.files is None else self.files.scores


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
    uncertainty: bool | str = False,
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
        uncertainty: each landmark's covariance, as ``build_map``'s ``uncertainty``
            (docs/guide/uncertainty.md): ``map.csv``'s ``cov_*`` columns, the tag map's
            ``covariance`` and ``map.png``'s 95 % ellipses.
    """
    from lfmdr_gym.experiments.mapping import method_and_params
    from lfmdr_gym.experiments.params import method_label, param_label
    from lfmdr_gym.experiments.scoring import map_history
    from lfmdr_gym.histories.observation_table import read_landmarks, read_observations
    from lfmdr_gym.histories.observations import landmark_ids, observations_to_history

    if out is not None and Path(out).exists() and not Path(out).is_dir():
        raise ValueError(f"cannot write to output directory {str(out)!r}: it is a file")
    table = read_observations(path)
    anchor_table = read_landmarks(anchors, what="anchors")
    truth_table = read_landmarks(truth, what="truth") if truth is not None else None
    # (it refuses anchors absent from the log, fewer than 3, or collinear)
    history = observations_to_history(table, anchor_table, truth=truth_table, sensor=sensor,
                                      bin_width=bin_width)
    landmarks = tuple(landmark_ids(history).tolist())
    if n_steps is not None:
        history = history.head(n_steps)
    label, chosen = method_and_params(method, history, params)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the map's own warnings are in result.warnings
        result = map_history(history, label, chosen, uncertainty=uncertainty)
    notes = tuple(landmark_notes(result.warnings, landmarks, history))
    files = None
    if out is not None:
        title = (f"{Path(path).name}, {method_label(label, chosen)}, "
                 f"{history.n_steps} steps")
        files = write_map_files(out, result, landmarks, history.anchor_ids,
                                history.anchor_positions, truth=truth_table, title=title,
                                frame=frame, plot=plot, notes=notes)
    return LogMap(result, history, landmarks, label, param_label(chosen), files, notes)

