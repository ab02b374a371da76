"""A map's files, as ``lfmdr map LOG`` writes them: a table, a tag map for other tools, a figure
and, with ground truth, the scores; all of one run written as a set (all or none).

Files written into the output folder:

- ``map.csv``: ``landmark, x, y`` (``z`` in 3-D), ``anchor`` and ``mapped`` (0/1), one row per
  landmark in the order of the log; landmark ids as they went in (a string id stays a string);
  an unmapped landmark has empty coordinates. When the map carries per-landmark covariances
  (``Map.covariances``, (M, d, d)), also ``cov_xx, cov_xy, cov_yy`` (and ``cov_xz, cov_yz,
  cov_zz`` in 3-D) [m²].
- ``map.json`` and ``map.yaml``: the same map as a tag map (the fields of :func:`tag_map`): the
  frame and units, and a list of ``{id, x, y[, z], anchor[, covariance]}``, one per mapped
  landmark; the unmapped ones listed by id.
- ``map.png``: the estimates (and the truth, when given) seen from above; a 3-D map in three
  orthographic views (top, front, side).
- ``scores.json`` (with ground truth): MPE and MOE (paper §4.3.2; :mod:`mappers.core.scores`)
  over the mapped landmarks the truth has, MPE over the non-anchor ones among them, and the ids
  of the landmarks the truth lacks (not scored) and of those left unmapped.
"""

from __future__ import annotations

import json
import math
import os
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from lfmdr_gym.atomic import atomic_file_set

__all__ = ["MapFiles", "covariance_columns", "map_rows", "score_against_truth", "tag_map",
           "write_map_files"]

_AXES = ("x", "y", "z")


@dataclass(frozen=True)
class MapFiles:
    """What :func:`write_map_files` wrote: the folder, its files, and the scores (None without
    ground truth)."""

    out: Path
    files: tuple[Path, ...]
    scores: dict[str, Any] | None


def _plain(value: Any) -> Any:
    """A landmark id as JSON has it: numpy integers as int, strings as str (as they went in)."""
    if isinstance(value, np.integer):
        return int(value)
    if isinstance(value, np.str_):
        return str(value)
    return value


def _number(value: float) -> float | None:
    return None if not math.isfinite(value) else float(value)


def _covariances(result: Any, m: int, d: int) -> np.ndarray | None:
    """The map's (M, d, d) covariances, or None when it has none (``Map.covariances`` is added
    by the uncertainty option; maps without it are read with ``getattr``)."""
    cov = getattr(result, "covariances", None)
    if cov is None:
        return None
    cov = np.asarray(cov, dtype=float)
    if cov.shape != (m, d, d):
        raise ValueError(f"the map's covariances have shape {cov.shape}, expected {(m, d, d)}")
    return cov


def covariance_columns(d: int) -> list[tuple[str, int, int]]:
    """(column, row, col) of a covariance's upper triangle: cov_xx, cov_xy, cov_yy (+ z); the
    columns of a map's ``map.csv`` when it has covariances."""
    pairs = [(i, j) for j in range(d) for i in range(j + 1)]  # xx, xy, yy, xz, yz, zz
    return [(f"cov_{_AXES[i]}{_AXES[j]}", i, j) for i, j in pairs]


def map_rows(result: Any, landmarks: Sequence[Any], anchor_rows: Sequence[int]) -> list[dict[str, Any]]:
    """One dict per landmark: ``landmark``, ``x``, ``y`` (``z``), ``anchor``, ``mapped`` (and the
    covariance's entries when the map has them); coordinates None where unmapped."""
    positions = np.asarray(result.positions, dtype=float)
    m, d = positions.shape
    if len(landmarks) != m:
        raise ValueError(f"{len(landmarks)} landmark ids for a map of {m} landmarks")
    anchors = {int(a) for a in anchor_rows}
    cov = _covariances(result, m, d)
    rows = []
    for k, lm in enumerate(landmarks):
        mapped = bool(np.all(np.isfinite(positions[k])))
        row: dict[str, Any] = {"landmark": _plain(lm)}
        row.update({_AXES[a]: float(positions[k, a]) if mapped else None for a in range(d)})
        row.update(anchor=int(k in anchors), mapped=int(mapped))
        if cov is not None:
            row.update({name: _number(cov[k, i, j]) if mapped else None
                        for name, i, j in covariance_columns(d)})
        rows.append(row)
    return rows


def _csv(rows: Sequence[Mapping[str, Any]]) -> str:
    """``map.csv``'s text; floats in their shortest exact form, an unmapped cell empty."""
    import csv
    import io

    buffer = io.StringIO()
    writer = csv.writer(buffer, lineterminator="\n")
    writer.writerow(list(rows[0]))
    for row in rows:
        writer.writerow(["" if v is None else repr(v) if isinstance(v, float) else v
                         for v in row.values()])
    return buffer.getvalue()


def tag_map(rows: Sequence[Mapping[str, Any]], *, frame: str = "map") -> dict[str, Any]:
    """The tag map of ``map.json`` / ``map.yaml``: ``frame`` (the anchors' frame, named as the
    user's tools call it), ``units`` ("m"), ``dimensions``, ``landmarks`` (one entry per mapped
    landmark: ``id``, coordinates, ``anchor`` and, when known, ``covariance`` as a d x d list)
    and ``unmapped`` (ids)."""
    d = sum(1 for a in _AXES if a in rows[0])
    entries, unmapped = [], []
    for row in rows:
        if not row["mapped"]:
            unmapped.append(row["landmark"])
            continue
        entry = {"id": row["landmark"], **{a: row[a] for a in _AXES[:d]},
                 "anchor": bool(row["anchor"])}
        if "cov_xx" in row:
            cov = [[None] * d for _ in range(d)]
            for name, i, j in covariance_columns(d):
                cov[i][j] = cov[j][i] = row[name]
            entry["covariance"] = cov
        entries.append(entry)
    return {"frame": frame, "units": "m", "dimensions": d, "landmarks": entries,
            "unmapped": unmapped}


def _yaml_scalar(value: Any) -> str:
    """One YAML scalar. Written by hand so that a core install needs no YAML library: strings
    are JSON strings (a valid YAML double-quoted scalar), floats always have a '.' before an
    exponent (else YAML 1.1 readers such as PyYAML take ``1e-05`` for a string)."""
    if value is None:
        return "null"
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, float):
        text = repr(value)
        mantissa, e, exponent = text.partition("e")
        if e and "." not in mantissa:
            text = f"{mantissa}.0e{exponent}"
        return text
    if isinstance(value, int):
        return str(value)
    return json.dumps(str(value))


def _yaml(doc: Mapping[str, Any]) -> str:
    """``map.yaml``: the tag map in block style (lists of scalars in flow style)."""
    lines = ["# landmark map written by lfmdr (localisation-free mapping)"]
    for key, value in doc.items():
        if key == "landmarks":
            lines.append("landmarks:" if value else "landmarks: []")
            for entry in value:
                for k, (name, v) in enumerate(entry.items()):
                    text = ("[" + ", ".join("[" + ", ".join(map(_yaml_scalar, r)) + "]" for r in v)
                            + "]") if name == "covariance" else _yaml_scalar(v)
                    lines.append(f"{'  - ' if k == 0 else '    '}{name}: {text}")
        elif isinstance(value, list):
            lines.append(f"{key}: [" + ", ".join(map(_yaml_scalar, value)) + "]")
        else:
            lines.append(f"{key}: {_yaml_scalar(value)}")
    return "\n".join(lines) + "\n"


def _truth_lookup(truth: Any) -> dict[Any, np.ndarray]:
    """Ground truth as id -> position: a mapping, or a table with ``landmark`` and ``x``, ``y``
    (``z``) columns (as :func:`lfmdr_gym.histories.observation_table.read_landmarks` gives)."""
    if isinstance(truth, Mapping):
        return {_plain(k): np.asarray(v, dtype=float) for k, v in truth.items()}
    columns = [a for a in _AXES if a in truth.columns]
    values = truth[columns].to_numpy(dtype=float)
    return {_plain(k): values[i] for i, k in enumerate(truth["landmark"].tolist())}


def score_against_truth(
    positions: np.ndarray,
    landmarks: Sequence[Any],
    anchor_rows: Sequence[int],
    truth: Any,
) -> dict[str, Any]:
    """Scores of a map against ground truth over the landmarks the truth has.

    Returns ``mpe`` [m] (the mapped landmarks the truth has, anchors included, as ``lfmdr map
    HISTORY.npz`` reports), ``mpe_nonanchor`` [m], ``moe`` [%] (paper §4.3.2; NaN below 3
    landmarks), ``n_scored``, and the ids ``missing_from_truth`` (not scored), ``unmapped`` and
    ``truth_not_in_log`` (landmarks of the truth the log never names). A NaN score is written
    as null.
    """
    from mappers import mean_orientation_error, mean_position_error

    lookup = _truth_lookup(truth)
    positions = np.asarray(positions, dtype=float)
    d = positions.shape[1]
    ids = [_plain(lm) for lm in landmarks]
    for lm, p in lookup.items():
        if p.shape != (d,):
            raise ValueError(f"truth of landmark {lm!r} has {p.size} coordinates, the map {d}")
    mapped = np.all(np.isfinite(positions), axis=1)
    present = np.array([lm in lookup for lm in ids], dtype=bool)
    anchors = np.zeros(len(ids), dtype=bool)
    anchors[np.asarray(anchor_rows, dtype=int)] = True
    true = np.array([lookup.get(lm, np.full(d, np.nan)) for lm in ids]).reshape(len(ids), d)
    scored = mapped & present

    def over(rows: np.ndarray, score: Any, least: int) -> float | None:
        if rows.sum() < least:
            return None
        if d == 2:
            return float(score(positions, true, exclude=np.flatnonzero(~rows).tolist()))
        # 3-D: mappers.core.scores is 2-D; MPE is the same mean distance, MOE is not defined
        return float(np.mean(np.linalg.norm(positions[rows] - true[rows], axis=1)))

    in_log = set(ids)
    return {
        "mpe": over(scored, mean_position_error, 1),
        "mpe_nonanchor": over(scored & ~anchors, mean_position_error, 1),
        "moe": over(scored, mean_orientation_error, 3) if d == 2 else None,  # (2-D triangles)
        "n_scored": int(scored.sum()),
        "n_scored_nonanchor": int((scored & ~anchors).sum()),
        "missing_from_truth": [lm for lm, p in zip(ids, present, strict=True) if not p],
        "unmapped": [lm for lm, m in zip(ids, mapped, strict=True) if not m],
        "truth_not_in_log": [lm for lm in lookup if lm not in in_log],
    }


def _plot(path: Path, rows: Sequence[Mapping[str, Any]], truth: Any, anchors: Mapping[int, Any],
          title: str, notes: Sequence[str], cov: np.ndarray | None = None) -> None:
    """``map.png``: estimates and truth seen from above (x, y), anchors (row -> known position)
    as squares; without truth, the estimates are labelled; with covariances ((M, d, d)), each
    estimate's 95 % ellipse (of its x-y block). A 3-D map (rows with ``z``) is drawn in three
    orthographic views (:func:`lfmdr_gym.experiments.figures.plot_views_3d`), each with the
    ellipses of its plane."""
    from lfmdr_gym.experiments.figures import plot_estimate, plot_views_3d

    axes = [a for a in _AXES if a in rows[0]] if rows else ["x", "y"]
    est = np.array([[np.nan if r[a] is None else r[a] for a in axes] for r in rows])
    lookup = _truth_lookup(truth) if truth is not None else {}
    true = np.array([lookup[r["landmark"]] if r["landmark"] in lookup else
                     np.asarray(anchors[k], dtype=float) if k in anchors else
                     np.full(len(axes), np.nan) for k, r in enumerate(rows)], dtype=float)
    if len(axes) == 3:
        plot_views_3d(est, true, sorted(anchors), path, title=title, notes=notes,
                      covariances=cov)
        return
    plot_estimate(est, true, sorted(anchors), path, title=title, notes=notes,
                  labels=[str(r["landmark"]) for r in rows],
                  covariances=None if cov is None else cov[:, :2, :2])


def write_map_files(
    out: str | os.PathLike,
    result: Any,
    landmarks: Sequence[Any],
    anchor_rows: Sequence[int],
    anchor_positions: Any,
    *,
    truth: Any = None,
    title: str = "",
    frame: str = "map",
    plot: bool = True,
    notes: Sequence[str] | None = None,
) -> MapFiles:
    """Write a map's files into ``out`` as one set (:func:`lfmdr_gym.atomic.atomic_file_set`):
    on any error ``out`` is left exactly as it was.

    Args:
        out: the output folder (created if missing).
        result: the ``mappers.Map`` (its ``positions``, (M, d); ``warnings``; ``covariances``
            when it has them).
        landmarks: the M landmark ids, one per row of ``result.positions``, as they went in.
        anchor_rows: rows of the anchors the user gave.
        anchor_positions: (A, d) their known positions (drawn where the truth lacks them).
        truth: None, or ground truth (a table ``landmark, x, y[, z]`` or a mapping id ->
            position): adds ``scores.json`` (:func:`score_against_truth`) and the truth to the
            figure.
        title: the figure's title.
        frame: the anchors' frame, named in the tag map.
        plot: write ``map.png`` (needs matplotlib).
        notes: the warnings written under the figure (default: ``result.warnings``; a log's
            map gives them naming landmark ids).
    """
    rows = map_rows(result, landmarks, anchor_rows)
    doc = tag_map(rows, frame=frame)
    scores = (score_against_truth(result.positions, landmarks, anchor_rows, truth)
              if truth is not None else None)
    out = Path(out)
    with atomic_file_set(out) as files:
        files.write_text("map.csv", _csv(rows))
        files.write_text("map.json", json.dumps(doc, indent=1) + "\n")
        files.write_text("map.yaml", _yaml(doc))
        if scores is not None:
            files.write_text("scores.json", json.dumps(scores, indent=1) + "\n")
        if plot:
            anchors = dict(zip((int(a) for a in anchor_rows), np.asarray(anchor_positions),
                               strict=True))
            _plot(files.path("map.png"), rows, truth, anchors, title,
                  tuple(result.warnings if notes is None else notes),
                  _covariances(result, len(rows), np.asarray(result.positions).shape[1]))
        names = files.names
    return MapFiles(out, tuple(out / n for n in names), scores)
