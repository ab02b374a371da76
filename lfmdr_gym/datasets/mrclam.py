"""UTIAS MRCLAM runs (real robots, real cameras) -> :class:`~lfmdr_gym.histories.history.History`.

A run directory holds ``Barcodes.dat``, ``Landmark_Groundtruth.dat`` and
``Robot<N>_Measurement.dat`` (4-line ``#`` header, CRLF, whitespace separated; see the
dataset's README). :func:`read_run` reads and filters the measurements; :func:`bin_run` and
:func:`load_mrclam` bin them into per-landmark histories (:func:`load_mrclam` returns a
:class:`History`: one sensor's, or range and bearing fused). This module only reads and bins:
mapping a run and scoring it is :func:`lfmdr_gym.experiments.mrclam.map_mrclam_run`.

Binning. Every robot is its own viewpoint, so bins are per robot: robot ``k``'s measurements
fall into bins of ``bin_width`` seconds on a grid that starts at the earliest time of all chosen
robots, and the histories of the robots are concatenated (robot 1's bins, then robot 2's, ...);
the history's ``timeline`` keeps each bin's robot and grid index. Bins in which a robot saw no
landmark carry no information and are dropped (``drop_empty_bins``). Within a bin a landmark's
bearing is the circular mean and its range the median of what was logged. A camera log says
what was seen, not what was looked at, so only sightings are observed entries (``History.mask``).

Data problems are never fixed silently: the filtering counts are in ``History.meta`` and the
returned :class:`MRCLAMReport`; ground-truth fixes (the documented DS1 swap of subjects 11 and 17)
are an option that warns when applied; a consistency check of the ground truth against
same-image range+bearing distances warns about anything else it finds; and a layout whose
co-observation graph falls apart (the clustered DS6) gets a warning. Ground truth (landmark
positions) is used only to place the anchors and to score.
"""

from __future__ import annotations

import os
import warnings
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from lfmdr_gym.checks import check_real
from lfmdr_gym.datasets.mrclam_layout import check_run_layout
from lfmdr_gym.histories.binning import assemble, cell_values, time_steps
from lfmdr_gym.histories.history import History
from mappers.core.align import check_anchor_ids
from mappers.core.sensors import (
    COLUMNS_PER_STEP,
    check_sensor,
    check_sensor_set,
    sensor_name,
    sensors_of,
)
from mappers.masked.coobservation import co_observation_components

__all__ = [
    "DEFAULT_BIN_WIDTH",
    "GROUNDTRUTH_FIXES",
    "KNOWN_GROUNDTRUTH_SWAPS",
    "MRCLAMDataWarning",
    "MRCLAMReport",
    "MRCLAMRun",
    "bin_run",
    "check_groundtruth",
    "corner_anchors",
    "image_pairs",
    "load_mrclam",
    "read_run",
    "run_meta",
]

ROBOT_SUBJECTS = (1, 2, 3, 4, 5)
GROUNDTRUTH_FIXES = ("known", "detect", "none")

# Documented ground-truth problems, identified by the file's own values (not the folder name),
# so a renamed copy of the run is still recognised. DS1: barcodes 18 and 61 are swapped relative
# to Landmark_Groundtruth.dat, i.e. the true positions of subjects 11 and 17 are exchanged.
KNOWN_GROUNDTRUTH_SWAPS: dict[str, dict[str, Any]] = {
    "MRCLAM_Dataset1": {
        "fingerprint": {11: (3.15071999, 2.38294871), 17: (0.03596156, -2.84396626)},
        "swap": (11, 17),
    },
}


class MRCLAMDataWarning(UserWarning):
    """A known or detected problem in an MRCLAM run (ground truth, layout, coverage)."""


def _warn(msg: str, sink: list[str]) -> None:
    sink.append(msg)
    warnings.warn(msg, MRCLAMDataWarning, stacklevel=3)


# ---------------------------------------------------------------------------------- reading
def _read_table(path: Path, ncols: int) -> np.ndarray:
    """Read an MRCLAM .dat file (``#`` header, CRLF tolerated) as an (n, ncols) float array."""
    if not path.is_file():
        raise FileNotFoundError(f"MRCLAM file missing: {path}")
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # empty files warn in numpy; handled below
            data = np.loadtxt(path, comments="#", ndmin=2)
    except ValueError as exc:
        raise ValueError(f"{path} is not a whitespace-separated MRCLAM table: {exc}") from exc
    if data.size == 0:
        return np.zeros((0, ncols))
    if data.shape[1] < ncols:
        raise ValueError(f"{path} has {data.shape[1]} columns, expected at least {ncols}")
    return data[:, :ncols]


@dataclass(frozen=True)
class MRCLAMReport:
    """What the loader kept, dropped and warned about (also stored in ``History.meta``)."""

    run: str
    robots: tuple[int, ...]
    rows: int
    robot_rows: int
    unknown_barcode_rows: int
    repeat_rows: int
    landmark_rows: int
    per_robot_landmark_rows: dict[int, int]
    groundtruth_fix: str
    warnings: tuple[str, ...] = ()

    @classmethod
    def from_meta(cls, meta: dict[str, Any]) -> MRCLAMReport:
        """The report of a loaded history, from its ``History.meta`` (:meth:`as_dict`'s fields)."""
        return cls(
            run=str(meta["run"]), robots=tuple(int(r) for r in meta["robots"]),
            rows=int(meta["rows"]), robot_rows=int(meta["robot_rows"]),
            unknown_barcode_rows=int(meta["unknown_barcode_rows"]),
            repeat_rows=int(meta["repeat_rows"]), landmark_rows=int(meta["landmark_rows"]),
            per_robot_landmark_rows={int(k): int(v)
                                     for k, v in meta["per_robot_landmark_rows"].items()},
            groundtruth_fix=str(meta["groundtruth_fix"]),
            warnings=tuple(str(w) for w in meta["warnings"]),
        )

    def as_dict(self) -> dict[str, Any]:
        return {
            "run": self.run,
            "robots": list(self.robots),
            "rows": self.rows,
            "robot_rows": self.robot_rows,
            "unknown_barcode_rows": self.unknown_barcode_rows,
            "repeat_rows": self.repeat_rows,
            "landmark_rows": self.landmark_rows,
            "per_robot_landmark_rows": {str(k): v for k, v in self.per_robot_landmark_rows.items()},
            "groundtruth_fix": self.groundtruth_fix,
            "warnings": list(self.warnings),
        }


@dataclass(frozen=True, eq=False)
class MRCLAMRun:
    """The filtered landmark measurements of one run, before binning.

    Attributes:
        name: the run directory's name.
        subjects: (M,) landmark subject numbers, sorted; row ``i`` of every matrix is ``subjects[i]``.
        truth: (M, 2) landmark ground truth [m] after any ground-truth fix (scoring only).
        obs: (n, 5) float array of kept measurements: robot, time [s], landmark index, range [m],
            bearing [rad]; sorted by robot then time.
        image: (n,) int64 id of the camera image a row came from (same robot and timestamp).
        report: filtering counts and warnings.
    """

    name: str
    subjects: np.ndarray
    truth: np.ndarray
    obs: np.ndarray
    image: np.ndarray
    report: MRCLAMReport

    @property
    def t0(self) -> float:
        return float(self.obs[:, 1].min()) if len(self.obs) else 0.0


def _fingerprint_matches(truth_by_subject: dict[int, np.ndarray], fp: dict[int, tuple]) -> bool:
    for s, xy in fp.items():
        if s not in truth_by_subject or np.max(np.abs(truth_by_subject[s] - np.asarray(xy))) > 1e-3:
            return False
    return True


def _read_subjects(run_dir: Path) -> tuple[dict[int, int], np.ndarray, dict[int, np.ndarray]]:
    """Barcode -> subject, the sorted landmark subjects, and each landmark's true position."""
    bc = _read_table(run_dir / "Barcodes.dat", 2).astype(np.int64)
    gt = _read_table(run_dir / "Landmark_Groundtruth.dat", 3)
    subjects = np.array(sorted(int(s) for s in gt[:, 0]), dtype=np.int64)
    if subjects.size < 3:
        raise ValueError(f"{run_dir}: Landmark_Groundtruth.dat lists {subjects.size} landmarks")
    truth = {int(s): gt[k, 1:3].astype(float) for k, s in enumerate(gt[:, 0])}
    return {int(b): int(s) for s, b in bc}, subjects, truth


def _known_fixes(truth: dict[int, np.ndarray], fixes: str, name: str, msgs: list[str]) -> str:
    """Apply (or only report) the documented ground-truth swaps the file's values match."""
    done = "none"
    for run, known in KNOWN_GROUNDTRUTH_SWAPS.items():
        if not _fingerprint_matches(truth, known["fingerprint"]):
            continue
        a, b = known["swap"]
        if fixes in ("known", "detect"):
            truth[a], truth[b] = truth[b], truth[a]
            done = f"swapped subjects {a} and {b} ({run})"
            _warn(f"{name}: Landmark_Groundtruth.dat matches {run}, whose ground truth of subjects "
                  f"{a} and {b} is swapped (documented; same-image range+bearing distances confirm "
                  "it); swapping them back for scoring. Pass groundtruth_fixes='none' "
                  "(--groundtruth-fixes none) to use the file as given.", msgs)
        else:
            _warn(f"{name}: Landmark_Groundtruth.dat matches {run}, whose ground truth of subjects "
                  f"{a} and {b} is known to be swapped; using it as given "
                  f"(groundtruth_fixes='none'), so scores for {a} and {b} are wrong.", msgs)
    return done


def _exact_repeats(subjects: np.ndarray, rows: np.ndarray) -> np.ndarray:
    """Rows with the same range and bearing as the previous kept row of their barcode (stale
    detector output logged again)."""
    repeat = np.zeros(len(rows), dtype=bool)
    last: dict[int, tuple[float, float]] = {}
    for k in range(len(rows)):
        key = int(subjects[k])
        rb = (rows[k, 2], rows[k, 3])
        if last.get(key) == rb:
            repeat[k] = True
        last[key] = rb
    return repeat


def _read_robot(path: Path, robot: int, barcode_to_subject: dict[int, int],
                index_of: dict[int, int], no_truth: list[int], counts: dict[str, int]) -> np.ndarray:
    """One robot's kept landmark rows as (robot, time, landmark index, range, bearing), sorted by
    time; ``counts`` gains what was read and dropped."""
    m = _read_table(path, 4)
    subj = np.array([barcode_to_subject.get(int(c), -1) for c in m[:, 1].astype(np.int64)],
                    dtype=np.int64)
    unknown, robot_rows = subj < 0, np.isin(subj, ROBOT_SUBJECTS)
    untrue = np.isin(subj, no_truth)
    counts["rows"] += len(m)
    counts["unknown"] += int(unknown.sum())
    counts["robot"] += int(robot_rows.sum())
    counts["no_truth"] += int(untrue.sum())
    keep = ~unknown & ~robot_rows & ~untrue
    m, subj = m[keep], subj[keep]
    order = np.argsort(m[:, 0], kind="stable")
    m, subj = m[order], subj[order]
    repeat = _exact_repeats(subj, m)
    counts["repeat"] += int(repeat.sum())
    m, subj = m[~repeat], subj[~repeat]
    idx = np.array([index_of[int(s)] for s in subj], dtype=float)
    return np.column_stack([np.full(len(m), robot, float), m[:, 0], idx, m[:, 2], m[:, 3]])


def _check_args(run_dir: Path, robots: Sequence[int], groundtruth_fixes: str) -> tuple[int, ...]:
    if groundtruth_fixes not in GROUNDTRUTH_FIXES:
        raise ValueError(f"groundtruth_fixes must be one of {GROUNDTRUTH_FIXES}, "
                         f"got {groundtruth_fixes!r}")
    robots = tuple(int(r) for r in robots)
    if not robots or len(set(robots)) != len(robots):
        raise ValueError(f"robots must be a non-empty list of distinct robot numbers, got {robots}")
    check_run_layout(run_dir, robots)  # what is missing, and where to get the dataset
    return robots


def _detected_fixes(run: MRCLAMRun, fixes: str, fix_desc: str, msgs: list[str]) -> str:
    """Check the ground truth against same-image range+bearing distances; swap what the check
    finds when asked to (``"detect"``), else warn."""
    swaps, bad = check_groundtruth(run)
    if swaps and fixes == "detect":
        for a, b in swaps:
            ia, ib = np.searchsorted(run.subjects, [a, b])
            run.truth[[ia, ib]] = run.truth[[ib, ia]]
        fix_desc = (fix_desc + "; " if fix_desc != "none" else "") + "detected swaps " + ", ".join(
            f"{a}<->{b}" for a, b in swaps)
        _warn(f"{run.name}: ground truth disagrees with same-image range+bearing distances; "
              f"swapping subjects {swaps} (groundtruth_fixes='detect').", msgs)
    elif bad:
        hint = f"; swapping {swaps} would explain it" if swaps else ""
        _warn(f"{run.name}: ground truth disagrees with same-image range+bearing distances for "
              f"{len(bad)} landmark pair(s) {bad[:6]}{hint}; scores involving them may be wrong "
              "(try groundtruth_fixes='detect', --groundtruth-fixes detect).", msgs)
    return fix_desc


def read_run(
    run_dir: str | os.PathLike,
    robots: Sequence[int] = ROBOT_SUBJECTS,
    *,
    groundtruth_fixes: str = "known",
) -> MRCLAMRun:
    """Read and filter one MRCLAM run directory.

    Drops rows whose barcode is a robot (subjects 1-5: they move), rows whose barcode is not in
    ``Barcodes.dat`` (misreads), and exact repeats (same range and bearing as the previous kept
    row of that robot for that barcode: stale detector output logged again).

    Args:
        run_dir: directory with ``Barcodes.dat``, ``Landmark_Groundtruth.dat`` and
            ``Robot<N>_Measurement.dat``.
        robots: robot subject numbers whose measurements to use.
        groundtruth_fixes: ``"known"`` applies documented fixes (the DS1 swap of subjects 11 and
            17, recognised from the file's values) with a warning; ``"detect"`` also applies swaps
            found by :func:`check_groundtruth`; ``"none"`` uses the file as given (a documented
            or detected problem still warns).
    """
    run_dir = Path(run_dir)
    robots = _check_args(run_dir, robots, groundtruth_fixes)
    barcode_to_subject, subjects, truth_by_subject = _read_subjects(run_dir)
    index_of = {int(s): i for i, s in enumerate(subjects)}
    no_truth = sorted(s for s in barcode_to_subject.values()
                      if s not in index_of and s not in ROBOT_SUBJECTS)
    msgs: list[str] = []
    fix_desc = _known_fixes(truth_by_subject, groundtruth_fixes, run_dir.name, msgs)
    truth = np.array([truth_by_subject[int(s)] for s in subjects])
    counts = dict.fromkeys(("rows", "robot", "unknown", "repeat", "no_truth"), 0)
    chunks = [_read_robot(run_dir / f"Robot{r}_Measurement.dat", r, barcode_to_subject, index_of,
                          no_truth, counts) for r in robots]
    obs = np.concatenate(chunks) if chunks else np.zeros((0, 5))
    if counts["no_truth"]:
        _warn(f"{run_dir.name}: dropped {counts['no_truth']} row(s) of subject(s) {no_truth}, "
              "which are in Barcodes.dat but neither robots (1-5) nor in "
              "Landmark_Groundtruth.dat", msgs)
    # camera image id: rows of one robot sharing a timestamp
    _, image = np.unique(obs[:, :2], axis=0, return_inverse=True)
    report = MRCLAMReport(
        run=run_dir.name, robots=robots, rows=counts["rows"], robot_rows=counts["robot"],
        unknown_barcode_rows=counts["unknown"], repeat_rows=counts["repeat"],
        landmark_rows=len(obs), groundtruth_fix=fix_desc, warnings=tuple(msgs),
        per_robot_landmark_rows={r: len(c) for r, c in zip(robots, chunks, strict=True)},
    )
    run = MRCLAMRun(run_dir.name, subjects, truth, obs, np.asarray(image, np.int64).ravel(), report)
    fix_desc = _detected_fixes(run, groundtruth_fixes, fix_desc, msgs)
    report = MRCLAMReport(**{**report.__dict__, "groundtruth_fix": fix_desc, "warnings": tuple(msgs)})
    return MRCLAMRun(run.name, subjects, run.truth, obs, run.image, report)


# ----------------------------------------------------------------- same-image pair geometry
def image_pairs(run: MRCLAMRun) -> np.ndarray:
    """All pairs of landmarks seen in the same camera image: (n, 6) array of
    i, j (i < j), r_i, r_j, b_i, b_j."""
    obs, image = run.obs, run.image
    order = np.argsort(image, kind="stable")
    img = image[order]
    o = obs[order]
    starts = np.flatnonzero(np.r_[True, img[1:] != img[:-1]])
    ends = np.r_[starts[1:], len(img)]
    out = []
    for s, e in zip(starts, ends, strict=True):
        if e - s < 2:
            continue
        a, b = np.triu_indices(e - s, 1)
        rows = o[s:e]
        i, j = rows[a, 2], rows[b, 2]
        swap = i > j
        ii, jj = np.where(swap, j, i), np.where(swap, i, j)
        ra, rb = np.where(swap, rows[b, 3], rows[a, 3]), np.where(swap, rows[a, 3], rows[b, 3])
        ba, bb = np.where(swap, rows[b, 4], rows[a, 4]), np.where(swap, rows[a, 4], rows[b, 4])
        keep = ii != jj
        out.append(np.column_stack([ii, jj, ra, rb, ba, bb])[keep])
    return np.concatenate(out) if out else np.zeros((0, 6))


def check_groundtruth(
    run: MRCLAMRun, *, min_pairs: int = 10, max_range: float = 4.0, tol: float = 0.5
) -> tuple[list[tuple[int, int]], list[tuple[int, int]]]:
    """Check the ground truth against distances measured without localisation.

    For every landmark pair seen together in at least ``min_pairs`` images with both ranges below
    ``max_range`` (long ranges are biased), the law of cosines gives the distance
    ``sqrt(r_i^2 + r_j^2 - 2 r_i r_j cos(b_i - b_j))``; its median is compared with the ground
    truth. Returns ``(swaps, bad)``: subject pairs whose exchange removes every disagreement
    larger than ``tol`` metres (empty if none does), and the disagreeing subject pairs.
    """
    p = image_pairs(run)
    if len(p) == 0:
        return [], []
    p = p[(p[:, 2] < max_range) & (p[:, 3] < max_range)]
    d = np.sqrt(np.maximum(p[:, 2] ** 2 + p[:, 3] ** 2 - 2 * p[:, 2] * p[:, 3] * np.cos(p[:, 4] - p[:, 5]), 0))
    m = len(run.subjects)
    key = p[:, 0].astype(int) * m + p[:, 1].astype(int)
    med: dict[tuple[int, int], float] = {}
    for k in np.unique(key):
        sel = key == k
        if sel.sum() >= min_pairs:
            med[(int(k // m), int(k % m))] = float(np.median(d[sel]))

    def bad_pairs(truth: np.ndarray) -> list[tuple[int, int]]:
        return [
            (i, j) for (i, j), v in med.items() if abs(np.linalg.norm(truth[i] - truth[j]) - v) > tol
        ]

    bad = bad_pairs(run.truth)
    subj = run.subjects
    bad_s = [(int(subj[i]), int(subj[j])) for i, j in bad]
    if not bad:
        return [], []
    involved = np.bincount(np.array(bad).ravel(), minlength=m)
    suspects = [int(i) for i in np.argsort(-involved)[:4] if involved[i] > 0]
    best: tuple[int, list[tuple[int, int]]] = (len(bad), [])
    for a_pos, a in enumerate(suspects):
        for b in range(m):
            if b == a or (b in suspects[:a_pos]):
                continue
            t = run.truth.copy()
            t[[a, b]] = t[[b, a]]
            n = len(bad_pairs(t))
            if n < best[0]:
                best = (n, [(int(subj[min(a, b)]), int(subj[max(a, b)]))])
    swaps = best[1] if best[0] == 0 else []
    return swaps, bad_s


# ------------------------------------------------------------------------------ binning
DEFAULT_BIN_WIDTH: dict[str, float] = {"visibility": 3.0, "bearing": 3.0, "range": 0.5,
                                       "range-bearing": 0.25}
"""Bin width [s] per sensor when none is given: co-observation gains from a few seconds of camera
sweep, while range pairs must come from (nearly) one viewpoint, so range bins stay near the
camera period (about 0.24 s); range and bearing fused (``"range-bearing"``) need both readings
from one viewpoint, so their bins stay at the camera period. ``benchmarks/bench_mrclam.py``
compares widths."""


def corner_anchors(positions: np.ndarray, n_anchors: int = 4) -> np.ndarray:
    """Indices of the objects nearest the corners of their bounding box (each used once).

    Corners are taken in the order (min x, min y), (max x, min y), (max x, max y), (min x, max y).
    """
    positions = np.asarray(positions, dtype=float)
    if not 3 <= n_anchors <= 4:
        raise ValueError(f"n_anchors must be 3 or 4 for corner anchors, got {n_anchors}")
    lo, hi = positions.min(axis=0), positions.max(axis=0)
    corners = [(lo[0], lo[1]), (hi[0], lo[1]), (hi[0], hi[1]), (lo[0], hi[1])][:n_anchors]
    ids: list[int] = []
    for c in corners:
        d = np.linalg.norm(positions - np.asarray(c), axis=1)
        d[ids] = np.inf
        ids.append(int(np.argmin(d)))
    return np.array(ids, dtype=np.int64)


def _resolve_anchors(run: MRCLAMRun, anchors: Sequence[int] | None) -> np.ndarray:
    """Anchor rows from landmark subject numbers (None: the 4 nearest the bounding-box corners)."""
    if anchors is None:
        return corner_anchors(run.truth)
    anchors = [int(a) for a in anchors]
    missing = [a for a in anchors if a not in set(run.subjects.tolist())]
    if missing:
        raise ValueError(f"anchors {missing} are not landmark subjects of {run.name} "
                         f"(landmarks: {run.subjects.tolist()})")
    return check_anchor_ids(np.searchsorted(run.subjects, anchors), len(run.subjects))


def bin_run(
    run: MRCLAMRun, sensor: str, bin_width: float, *, drop_empty_bins: bool = True
) -> tuple[np.ndarray, np.ndarray, dict[str, Any], np.ndarray]:
    """Per-robot time bins -> ``(matrix, mask, info, timeline)`` for a :class:`History`.

    Robot ``k``'s rows fall into bins of ``bin_width`` seconds on a grid that starts at the
    earliest time of all chosen robots; the robots' bins are concatenated (robot 1's, then robot
    2's, ...). ``timeline`` gives each bin's robot (its position in ``run.report.robots``) and
    index on the grid. Only what was seen is known, so ``mask`` is True exactly where a landmark
    was sensed in the bin. Bearing is the circular mean and range the median of the bin's
    readings (:mod:`lfmdr_gym.histories.binning` bins every log alike).
    """
    check_sensor(sensor)
    check_real("bin_width", bin_width, low=0.0, low_open=True)  # [s]
    obs, robots = run.obs, list(run.report.robots)
    if len(obs) == 0:
        raise ValueError(f"{run.name}: no landmark measurements left after filtering")
    robot_pos = np.searchsorted(robots, obs[:, 0]) if robots == sorted(robots) else np.array(
        [robots.index(int(r)) for r in obs[:, 0]]
    )
    steps = time_steps(robot_pos, obs[:, 1], len(robots), bin_width,
                       drop_empty_bins=drop_empty_bins)
    m, n = len(run.subjects), steps.n_steps
    cells = cell_values((sensor,), obs[:, 2].astype(np.int64), steps.step, (m, n),
                        bearing=obs[:, 4], range_=obs[:, 3])
    info = {
        "bin_width": float(bin_width),
        "n_bins": n,
        "bins_per_robot": {str(r): int(np.sum(steps.timeline[:, 0] == k))
                           for k, r in enumerate(robots)},
        "drop_empty_bins": bool(drop_empty_bins),
        "observed_fraction": [round(float(f), 5)
                              for f in np.bincount(cells.landmark, minlength=m) / n],
    }
    matrix, mask = assemble(cells, sensor, sparse=False)
    return matrix, mask, info, steps.timeline


def run_meta(run: MRCLAMRun, sensor: str, anchor_ids: np.ndarray, seen: np.ndarray,
             min_co: int = 3) -> dict[str, Any]:
    """``History.meta`` of a binned run, and the warnings of what its robots saw (each also
    warned): landmarks never sighted, and a co-observation graph that falls apart.

    ``seen``: (M, N) bool, True where a landmark was sighted in a step; ``min_co``: a pair seen
    together in fewer steps is not linked. The meta holds the run, its subjects and anchors, the
    groups of the graph and the fields of :class:`MRCLAMReport` (its warnings these and the
    loader's); the bins' counts are the caller's to add.
    """
    msgs, robots = list(run.report.warnings), list(run.report.robots)
    comps = co_observation_components(seen, min_co)
    never = [int(run.subjects[i]) for i in np.flatnonzero(~seen.any(axis=1))]
    if never:
        _warn(f"{run.name}: landmark(s) {never} were never observed by robots {robots}; "
              "they cannot be mapped", msgs)
    if len(comps) > 1:
        groups = [[int(run.subjects[i]) for i in c] for c in comps]
        _warn(f"{run.name}: the co-observation graph falls apart into {len(comps)} groups "
              f"{groups} (pairs seen together in >= {min_co} bins): the relative placement of the "
              "groups is not measured (a clustered layout?); a map of it places them by anchors "
              "and lower bounds only — treat it as unreliable.", msgs)
    report = MRCLAMReport(**{**run.report.__dict__, "warnings": tuple(msgs)})
    return {
        "source": "MRCLAM",
        "sensor": sensor,
        "subjects": run.subjects.tolist(),
        "anchor_subjects": run.subjects[anchor_ids].tolist(),
        "co_observation_groups": [[int(run.subjects[i]) for i in c] for c in comps],
        **report.as_dict(),
    }


def load_mrclam(
    run_dir: str | os.PathLike,
    sensor: str = "visibility",
    *,
    robots: Sequence[int] = ROBOT_SUBJECTS,
    bin_width: float | None = None,
    anchors: Sequence[int] | None = None,
    groundtruth_fixes: str = "known",
    drop_empty_bins: bool = True,
    min_co: int = 3,
) -> History:
    """Load an MRCLAM run as a :class:`History` (with its mask and timeline).

    Args:
        run_dir: the run's directory (``MRCLAM_DatasetN`` layout).
        sensor: ``"visibility"``, ``"bearing"`` or ``"range"``; or ``"range-bearing"`` (both
            readings of every sighting, binned alike: a fused History whose ``parts`` are the
            range and the bearing histories, as ``lfmdr mrclam --sensor range-bearing`` maps).
        robots: robot subject numbers to use (their per-robot bins are concatenated).
        bin_width: seconds per bin; None = :data:`DEFAULT_BIN_WIDTH` of the sensor.
        anchors: landmark *subject numbers* of the anchors; None = the 4 landmarks nearest the
            corners of the landmarks' bounding box (ground truth places the anchors only).
        groundtruth_fixes: see :func:`read_run`.
        drop_empty_bins: drop bins in which a robot saw no landmark.
        min_co: a pair of landmarks seen together in fewer bins is not linked in the
            co-observation graph; a graph that falls apart warns (:class:`MRCLAMDataWarning`).

    Row ``i`` of the history is landmark ``meta["subjects"][i]``; ``object_positions`` is the
    motion-capture ground truth (scoring only); ``timeline`` says which robot and bin each
    column (pair) comes from. What the loader filtered and warned about is in ``meta`` (the
    fields of :class:`MRCLAMReport`; :meth:`MRCLAMReport.from_meta` gives the report back).
    """
    key = check_sensor_set(sensor)
    name = sensor_name(key)
    parts = sensors_of(name)
    if bin_width is None and name not in DEFAULT_BIN_WIDTH:
        raise ValueError(f"no default bin width for {name!r}: give bin_width (seconds)")
    run = read_run(run_dir, robots, groundtruth_fixes=groundtruth_fixes)
    bw = DEFAULT_BIN_WIDTH[name] if bin_width is None else bin_width
    binned = {s: bin_run(run, s, bw, drop_empty_bins=drop_empty_bins) for s in parts}
    anchor_ids = _resolve_anchors(run, anchors)
    # co-observation from the sightings: the mask of a sensor that keeps every one of them
    first = next(s for s in ("range", "visibility", "bearing") if s in binned)
    _, mask, info, timeline = binned[first]
    meta = run_meta(run, name, anchor_ids, mask[:, :: COLUMNS_PER_STEP[first]], min_co)
    meta.update(info)
    if len(parts) == 1:
        matrix, mask = binned[name][0], binned[name][1]
    else:
        matrix = {s: binned[s][0] for s in parts}
        mask = {s: binned[s][1] for s in parts}
    return History(sensor=name, matrix=matrix, object_positions=run.truth,
                   anchor_ids=anchor_ids, anchor_positions=run.truth[anchor_ids], mask=mask,
                   meta=meta, timeline=timeline)
