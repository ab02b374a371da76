"""UTIAS MRCLAM runs (real robots, real cameras) -> :class:`~lfmdr_gym.history.History`.

A run directory holds ``Barcodes.dat``, ``Landmark_Groundtruth.dat`` and
``Robot<N>_Measurement.dat`` (4-line ``#`` header, CRLF, whitespace separated; see the
dataset's README). :func:`load_mrclam` reads it, filters the measurements and bins them into
per-landmark histories; :func:`map_mrclam_run` maps a run and scores it against motion capture.

Binning. Every robot is its own viewpoint, so bins are per robot: robot ``k``'s measurements
fall into bins of ``bin_width`` seconds on a grid that starts at the earliest time of all chosen
robots, and the histories of the robots are concatenated (robot 1's bins, then robot 2's, ...).
Bins in which a robot saw no landmark carry no information for any mapper here and are dropped
(``drop_empty_bins``). Within a bin a landmark's bearing is the circular mean and its range the
median of what was logged.

Data problems are never fixed silently: the filtering counts are in ``History.meta`` and the
returned :class:`MRCLAMReport`; ground-truth fixes (the documented DS1 swap of subjects 11 and 17)
are an option that warns when applied; a consistency check of the ground truth against
same-image range+bearing distances warns about anything else it finds; and a layout whose
co-observation graph falls apart (the clustered DS6) gets a warning.

Ground truth (landmark positions) is used only to place the anchors and to score. Mapping uses
the masked methods of :mod:`mappers.missing` (their assumptions are listed there): by default
``range-quantile`` for range and ``covis-ensemble`` (the mean of covis-power maps over
several bin widths, :data:`ENSEMBLE_METHOD`) for visibility and bearing; ``"naive"`` is the
straightforward baseline. Measured figures: ``python benchmarks/bench_mrclam.py``.
"""

from __future__ import annotations

import os
import warnings
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from lfmdr_gym.atomic import atomic_write_text
from lfmdr_gym.history import History

__all__ = [
    "KNOWN_GROUNDTRUTH_SWAPS",
    "MODES",
    "DEFAULT_MODE_METHOD",
    "ENSEMBLE_METHOD",
    "MRCLAMDataWarning",
    "MRCLAMMap",
    "MRCLAMReport",
    "MRCLAMRun",
    "check_groundtruth",
    "co_observation_components",
    "corner_anchors",
    "load_mrclam",
    "map_mrclam_run",
    "read_run",
]

MODES = ("visibility", "bearing", "range")
ROBOT_SUBJECTS = (1, 2, 3, 4, 5)

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
    if not run_dir.is_dir():
        raise FileNotFoundError(f"run_dir {run_dir} is not a directory")
    if groundtruth_fixes not in ("known", "detect", "none"):
        raise ValueError(
            f"groundtruth_fixes must be 'known', 'detect' or 'none', got {groundtruth_fixes!r}"
        )
    robots = tuple(int(r) for r in robots)
    if not robots or len(set(robots)) != len(robots):
        raise ValueError(f"robots must be a non-empty list of distinct robot numbers, got {robots}")
    for r in robots:
        if not (run_dir / f"Robot{r}_Measurement.dat").is_file():
            raise ValueError(f"robots: no Robot{r}_Measurement.dat in {run_dir}")

    bc = _read_table(run_dir / "Barcodes.dat", 2).astype(np.int64)
    barcode_to_subject = {int(b): int(s) for s, b in bc}
    gt = _read_table(run_dir / "Landmark_Groundtruth.dat", 3)
    subjects = np.array(sorted(int(s) for s in gt[:, 0]), dtype=np.int64)
    if subjects.size < 3:
        raise ValueError(f"{run_dir}: Landmark_Groundtruth.dat lists {subjects.size} landmarks")
    truth_by_subject = {int(s): gt[k, 1:3].astype(float) for k, s in enumerate(gt[:, 0])}
    index_of = {int(s): i for i, s in enumerate(subjects)}
    robot_subjects = set(ROBOT_SUBJECTS)
    no_truth = sorted(
        s for s in barcode_to_subject.values() if s not in index_of and s not in robot_subjects
    )

    msgs: list[str] = []
    fix_desc = "none"
    for name, known in KNOWN_GROUNDTRUTH_SWAPS.items():
        if _fingerprint_matches(truth_by_subject, known["fingerprint"]):
            a, b = known["swap"]
            if groundtruth_fixes in ("known", "detect"):
                truth_by_subject[a], truth_by_subject[b] = truth_by_subject[b], truth_by_subject[a]
                fix_desc = f"swapped subjects {a} and {b} ({name})"
                _warn(
                    f"{run_dir.name}: Landmark_Groundtruth.dat matches {name}, whose ground truth "
                    f"of subjects {a} and {b} is swapped (documented; same-image range+bearing "
                    f"distances confirm it); swapping them back for scoring. "
                    f"Pass groundtruth_fixes='none' to use the file as given.",
                    msgs,
                )
            else:
                _warn(
                    f"{run_dir.name}: Landmark_Groundtruth.dat matches {name}, whose ground truth "
                    f"of subjects {a} and {b} is known to be swapped; using it as given "
                    f"(groundtruth_fixes='none'), so scores for {a} and {b} are wrong.",
                    msgs,
                )
    truth = np.array([truth_by_subject[int(s)] for s in subjects])

    n_rows = n_robot = n_unknown = n_repeat = n_no_truth = 0
    per_robot: dict[int, int] = {}
    chunks: list[np.ndarray] = []
    for r in robots:
        m = _read_table(run_dir / f"Robot{r}_Measurement.dat", 4)
        n_rows += len(m)
        codes = m[:, 1].astype(np.int64)
        subj = np.array([barcode_to_subject.get(int(c), -1) for c in codes], dtype=np.int64)
        unknown = subj < 0
        robot = np.isin(subj, list(robot_subjects))
        untrue = np.isin(subj, no_truth)
        n_unknown += int(unknown.sum())
        n_robot += int(robot.sum())
        n_no_truth += int(untrue.sum())
        keep = ~unknown & ~robot & ~untrue
        m, subj = m[keep], subj[keep]
        order = np.argsort(m[:, 0], kind="stable")
        m, subj = m[order], subj[order]
        # exact repeats: same range and bearing as the previous row for that barcode
        repeat = np.zeros(len(m), dtype=bool)
        last: dict[int, tuple[float, float]] = {}
        for k in range(len(m)):
            key = int(subj[k])
            rb = (m[k, 2], m[k, 3])
            if last.get(key) == rb:
                repeat[k] = True
            last[key] = rb
        n_repeat += int(repeat.sum())
        m, subj = m[~repeat], subj[~repeat]
        per_robot[r] = len(m)
        idx = np.array([index_of[int(s)] for s in subj], dtype=float)
        chunks.append(np.column_stack([np.full(len(m), r, float), m[:, 0], idx, m[:, 2], m[:, 3]]))
    obs = np.concatenate(chunks) if chunks else np.zeros((0, 5))
    if n_no_truth:
        _warn(
            f"{run_dir.name}: dropped {n_no_truth} row(s) of subject(s) {no_truth}, which are in "
            "Barcodes.dat but neither robots (1-5) nor in Landmark_Groundtruth.dat",
            msgs,
        )
    # camera image id: rows of one robot sharing a timestamp
    _, image = np.unique(obs[:, :2], axis=0, return_inverse=True)
    image = np.asarray(image, dtype=np.int64).ravel()

    report = MRCLAMReport(
        run=run_dir.name,
        robots=robots,
        rows=n_rows,
        robot_rows=n_robot,
        unknown_barcode_rows=n_unknown,
        repeat_rows=n_repeat,
        landmark_rows=len(obs),
        per_robot_landmark_rows=per_robot,
        groundtruth_fix=fix_desc,
        warnings=tuple(msgs),
    )
    run = MRCLAMRun(run_dir.name, subjects, truth, obs, image, report)

    # consistency check of the ground truth against same-image range+bearing distances
    swaps, bad = check_groundtruth(run)
    if swaps and groundtruth_fixes == "detect":
        for a, b in swaps:
            ia, ib = index_of[a], index_of[b]
            truth[[ia, ib]] = truth[[ib, ia]]
        fix_desc = (fix_desc + "; " if fix_desc != "none" else "") + "detected swaps " + ", ".join(
            f"{a}<->{b}" for a, b in swaps
        )
        _warn(
            f"{run_dir.name}: ground truth disagrees with same-image range+bearing distances; "
            f"swapping subjects {swaps} (groundtruth_fixes='detect').",
            msgs,
        )
    elif bad:
        hint = f"; swapping {swaps} would explain it" if swaps else ""
        _warn(
            f"{run_dir.name}: ground truth disagrees with same-image range+bearing distances for "
            f"{len(bad)} landmark pair(s) {bad[:6]}{hint}; scores involving them may be wrong "
            f"(try groundtruth_fixes='detect').",
            msgs,
        )
    report = MRCLAMReport(**{**report.__dict__, "groundtruth_fix": fix_desc, "warnings": tuple(msgs)})
    return MRCLAMRun(run_dir.name, subjects, truth, obs, image, report)


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
DEFAULT_BIN_WIDTH: dict[str, float] = {"visibility": 3.0, "bearing": 3.0, "range": 0.5}
"""Bin width [s] per mode when none is given. Chosen by measurement (benchmarks/bench_mrclam.py):
co-visibility gains from a few seconds of camera sweep; range pairs must come from (nearly) one
viewpoint, so range bins stay near the camera period (about 0.24 s)."""


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
    if anchors is None:
        return corner_anchors(run.truth)
    anchors = [int(a) for a in anchors]
    missing = [a for a in anchors if a not in set(run.subjects.tolist())]
    if missing:
        raise ValueError(f"anchors {missing} are not landmark subjects of {run.name} "
                         f"(landmarks: {run.subjects.tolist()})")
    if len(set(anchors)) != len(anchors) or len(anchors) < 3:
        raise ValueError(f"anchors must be at least 3 distinct landmark subjects, got {anchors}")
    return np.searchsorted(run.subjects, anchors).astype(np.int64)


def bin_run(
    run: MRCLAMRun, mode: str, bin_width: float, *, drop_empty_bins: bool = True
) -> tuple[np.ndarray, np.ndarray | None, dict[str, Any]]:
    """Per-robot time bins -> ``(matrix, mask, info)`` for a :class:`History` of ``mode``.

    Visibility: 1 where the landmark was seen in the bin (mask None: every bin is an
    observation). Bearing: (cos, sin) of the circular mean bearing, range: median range, both
    with a mask of the observed entries (unobserved entries are 0).
    """
    if mode not in MODES:
        raise ValueError(f"mode must be one of {MODES}, got {mode!r}")
    if not (isinstance(bin_width, (int, float)) and np.isfinite(bin_width) and bin_width > 0):
        raise ValueError(f"bin_width must be a positive number of seconds, got {bin_width!r}")
    obs = run.obs
    M = len(run.subjects)
    robots = list(run.report.robots)
    if len(obs) == 0:
        raise ValueError(f"{run.name}: no landmark measurements left after filtering")
    t0 = run.t0
    n_per_robot = int(np.floor((obs[:, 1].max() - t0) / bin_width)) + 1
    robot_pos = np.searchsorted(robots, obs[:, 0]) if robots == sorted(robots) else np.array(
        [robots.index(int(r)) for r in obs[:, 0]]
    )
    col = robot_pos * n_per_robot + np.floor((obs[:, 1] - t0) / bin_width).astype(np.int64)
    if drop_empty_bins:
        used, inv = np.unique(col, return_inverse=True)
    else:
        used = np.arange(len(robots) * n_per_robot)
        inv = col
    inv = np.asarray(inv).ravel()
    N = len(used)
    li = obs[:, 2].astype(np.int64)
    seen_count = np.zeros((M, N))
    np.add.at(seen_count, (li, inv), 1.0)
    seen = seen_count > 0
    bins_per_robot = {
        str(r): int(np.sum((used // n_per_robot) == k)) for k, r in enumerate(robots)
    }
    info = {
        "bin_width": float(bin_width),
        "n_bins": int(N),
        "bins_per_robot": bins_per_robot,
        "drop_empty_bins": bool(drop_empty_bins),
        "observed_fraction": [round(float(f), 5) for f in seen.mean(axis=1)],
    }
    if mode == "visibility":
        return seen.astype(np.float64), None, info
    if mode == "bearing":
        c = np.zeros((M, N))
        s = np.zeros((M, N))
        np.add.at(c, (li, inv), np.cos(obs[:, 4]))
        np.add.at(s, (li, inv), np.sin(obs[:, 4]))
        norm = np.hypot(c, s)
        ok = seen & (norm > 1e-12)
        c = np.where(ok, c / np.where(ok, norm, 1), 0.0)
        s = np.where(ok, s / np.where(ok, norm, 1), 0.0)
        matrix = np.empty((M, 2 * N))
        matrix[:, 0::2], matrix[:, 1::2] = c, s
        mask = np.repeat(ok, 2, axis=1)
        return matrix, mask, info
    # range: median of the bin's readings
    key = li * N + inv
    order = np.argsort(key, kind="stable")
    ks, rs = key[order], obs[order, 3]
    starts = np.flatnonzero(np.r_[True, ks[1:] != ks[:-1]])
    meds = np.array([np.median(seg) for seg in np.split(rs, starts[1:])])
    matrix = np.zeros((M, N))
    matrix.flat[ks[starts]] = meds
    return matrix, seen.copy(), info


def co_observation_components(seen: np.ndarray, min_co: int = 3) -> list[list[int]]:
    """Connected components (object indices) of the graph joining objects sensed together in
    at least ``min_co`` steps."""
    from scipy.sparse import csr_matrix
    from scipy.sparse.csgraph import connected_components

    S = np.asarray(seen, dtype=float)
    C = S @ S.T
    np.fill_diagonal(C, 0)
    n, labels = connected_components(csr_matrix(C >= min_co), directed=False)
    return [np.flatnonzero(labels == k).tolist() for k in range(n)]


def load_mrclam(
    run_dir: str | os.PathLike,
    mode: str = "visibility",
    *,
    robots: Sequence[int] = ROBOT_SUBJECTS,
    bin_width: float | None = None,
    anchors: Sequence[int] | None = None,
    groundtruth_fixes: str = "known",
    drop_empty_bins: bool = True,
    min_co: int = 3,
) -> tuple[History, MRCLAMReport]:
    """Load an MRCLAM run as a :class:`History` of one sensor mode, plus the filtering report.

    Args:
        run_dir: the run's directory (``MRCLAM_DatasetN`` layout).
        mode: ``"visibility"``, ``"bearing"`` or ``"range"``.
        robots: robot subject numbers to use (their per-robot bins are concatenated).
        bin_width: seconds per bin; None = :data:`DEFAULT_BIN_WIDTH` of the mode.
        anchors: landmark *subject numbers* of the anchors; None = the 4 landmarks nearest the
            corners of the landmarks' bounding box (ground truth places the anchors only).
        groundtruth_fixes: see :func:`read_run`.
        drop_empty_bins: drop bins in which a robot saw no landmark.
        min_co: a pair of landmarks seen together in fewer bins is not linked in the
            co-observation graph; a graph that falls apart warns (:class:`MRCLAMDataWarning`).

    Row ``i`` of the history is landmark ``meta["subjects"][i]``; ``object_positions`` is the
    motion-capture ground truth (scoring only).
    """
    if mode not in MODES:
        raise ValueError(f"mode must be one of {MODES}, got {mode!r}")
    run = read_run(run_dir, robots, groundtruth_fixes=groundtruth_fixes)
    bw = DEFAULT_BIN_WIDTH[mode] if bin_width is None else bin_width
    matrix, mask, info = bin_run(run, mode, bw, drop_empty_bins=drop_empty_bins)
    anchor_ids = _resolve_anchors(run, anchors)
    msgs = list(run.report.warnings)
    seen = matrix > 0 if mask is None else mask[:, :: (2 if mode == "bearing" else 1)]
    comps = co_observation_components(seen, min_co)
    never = [int(run.subjects[i]) for i in np.flatnonzero(~seen.any(axis=1))]
    if never:
        _warn(f"{run.name}: landmark(s) {never} were never observed by robots {list(robots)}; "
              "they cannot be mapped", msgs)
    if len(comps) > 1:
        groups = [[int(run.subjects[i]) for i in c] for c in comps]
        _warn(
            f"{run.name}: the co-observation graph falls apart into {len(comps)} groups "
            f"{groups} (pairs seen together in >= {min_co} bins): the relative placement of the "
            "groups is not measured (a clustered layout?); a map of it places them by anchors "
            "and lower bounds only — treat it as unreliable.",
            msgs,
        )
    report = MRCLAMReport(**{**run.report.__dict__, "warnings": tuple(msgs)})
    meta = {
        "source": "MRCLAM",
        "mode": mode,
        "subjects": run.subjects.tolist(),
        "anchor_subjects": run.subjects[anchor_ids].tolist(),
        "co_observation_groups": [[int(run.subjects[i]) for i in c] for c in comps],
        **report.as_dict(),
        **info,
    }
    history = History(
        sensor=mode,
        matrix=matrix,
        object_positions=run.truth,
        anchor_ids=anchor_ids,
        anchor_positions=run.truth[anchor_ids],
        mask=mask,
        meta=meta,
    )
    return history, report


# ------------------------------------------------------------------------------ mapping
ENSEMBLE_METHOD = "covis-ensemble"
"""The mean of ``covis-power`` maps (or ``member="covis-nonmetric"``; anchors fixed) over the
run binned at every width of :data:`ENSEMBLE_BIN_WIDTHS` and each ``min_co`` of
:data:`ENSEMBLE_MIN_CO` (see :func:`mappers.missing.ensemble_embedding`). A single map moves by
+-0.3 m with the bin width, and the width that is best on one run is not on another; the mean
over a fixed spread needs no setting choice. Parameters: ``bin_widths``, ``min_co``
(sequences), ``member`` (``"covis-power"`` or ``"covis-nonmetric"``), ``power`` (covis-power's
exponent), ``nearness_weight`` (bearing only: scale the dissimilarities by the landmarks' relative
nearness from bearing parallax between images of one robot,
:func:`mappers.missing.parallax_nearness`; measured without gain, off by default). Assumptions: those of the member method (mappers/missing.py): the chance of seeing
two landmarks in one bin falls with their distance the same way everywhere (covis-power: as
one power law)."""
ENSEMBLE_BIN_WIDTHS: tuple[float, ...] = (1.0, 1.5, 2.0, 3.0, 4.0, 5.0)
ENSEMBLE_MIN_CO: tuple[int, ...] = (3, 5)
ENSEMBLE_MEMBERS = ("covis-power", "covis-nonmetric")

DEFAULT_MODE_METHOD: dict[str, str] = {
    "visibility": ENSEMBLE_METHOD,
    "bearing": ENSEMBLE_METHOD,
    "range": "range-quantile",
}
"""Method used by :func:`map_mrclam_run` when none is given (best measured, leave-one-run-out,
benchmarks/bench_mrclam.py). Bearing uses only the pattern of what was seen: no bearing-specific
dissimilarity measured better than it, bearing parallax between images included (see the module
docstring of mappers/missing.py; ``--candidates covis-ensemble,covis-ensemble/parallax``)."""

NAIVE_METHOD = "naive"
"""The straightforward baseline: zero-filled history, rows L2-normalised, unweighted SMACOF from
classical MDS, affine fit to the anchors (the paper's pipeline applied to the binned log)."""


@dataclass(frozen=True, eq=False)
class MRCLAMMap:
    """A map of one MRCLAM run and its scores against motion capture.

    Attributes:
        run, mode, method, params: what was mapped and how.
        subjects: (M,) landmark subject numbers, one per row of ``positions``.
        positions: (M, 2) estimates in the ground-truth frame (anchors included; NaN = unmapped).
        truth: (M, 2) ground truth (after ``groundtruth_fixes``).
        anchor_subjects: subjects used as anchors.
        mpe: mean position error [m] over the mapped non-anchor landmarks.
        moe: mean orientation error [%] over the mapped non-anchor landmarks.
        centroid_mpe: MPE of placing every non-anchor landmark at the anchors' centroid.
        warnings: data and mapping warnings (also issued as :class:`MRCLAMDataWarning`).
        report: the loader's filtering report.
        history_meta: ``History.meta`` of the binned history.
        csv_path, png_path: files written (None when ``out`` is None).
    """

    run: str
    mode: str
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


def naive_map(history: History, random_state: int = 0) -> np.ndarray:
    """The baseline pipeline on a zero-filled history: L2-normalised rows, unweighted SMACOF
    (started from classical MDS), affine fit to the anchors. Returns (M, 2) positions."""
    from mappers.align import apply_affine, fit_affine
    from mappers.smacof import WeightedSMACOF

    X = np.where(history.mask, history.matrix, 0.0) if history.mask is not None else history.matrix
    norms = np.linalg.norm(X, axis=1, keepdims=True)
    out = np.full((history.n_objects, 2), np.nan)
    ok = norms[:, 0] > 0
    Y = WeightedSMACOF(init="lpca", random_state=random_state).fit_transform(X[ok] / norms[ok])
    idx = np.flatnonzero(ok)
    sub = np.searchsorted(idx, history.anchor_ids)
    out[ok] = apply_affine(Y, fit_affine(Y[sub], history.anchor_positions))
    return out


def _write_csv(path: Path, subjects: np.ndarray, positions: np.ndarray) -> None:
    lines = ["subject,x,y"]
    for s, (x, y) in zip(subjects, positions, strict=True):
        lines.append(f"{int(s)},{'' if np.isnan(x) else f'{x:.6f}'},{'' if np.isnan(y) else f'{y:.6f}'}")
    atomic_write_text(path, "\n".join(lines) + "\n")


def _plot(path: Path, result: MRCLAMMap) -> None:
    from lfmdr_gym.experiments.figures import plot_estimate

    anchors = np.flatnonzero(np.isin(result.subjects, result.anchor_subjects))
    title = (f"{result.run} {result.mode} ({result.method}): MPE {result.mpe:.2f} m, "
             f"MOE {result.moe:.1f} %")
    if result.warnings:
        first = result.warnings[0]
        title += f"\nWARNING ({len(result.warnings)}): {first[:80]}{'...' if len(first) > 80 else ''}"
    plot_estimate(result.positions, result.truth, anchors, path, title=title,
                  labels=result.subjects)


def map_mrclam_run(
    run_dir: str | os.PathLike,
    mode: str = "visibility",
    robots: Sequence[int] = ROBOT_SUBJECTS,
    method: str | None = None,
    anchors: Sequence[int] | None = None,
    out: str | os.PathLike | None = None,
    bin_width: float | None = None,
    *,
    groundtruth_fixes: str = "known",
    plot: bool = True,
    **params: Any,
) -> MRCLAMMap:
    """Map one MRCLAM run from one sensor mode and score it against motion capture.

    The parameters map 1:1 onto ``lfmdr mrclam RUN_DIR --mode MODE --robots 1,2,3,4,5
    --method M --anchors S1,S2,S3,S4 --out DIR --bin-width SECONDS``.

    Args:
        run_dir: the run's directory.
        mode: ``"visibility"``, ``"bearing"`` or ``"range"``.
        robots: robot subject numbers whose logs to use.
        method: a masked method of :data:`mappers.missing.MASKED_METHODS`
            (``"covis-nonmetric"``, ``"range-quantile"``, ``"masked-euclidean"``, ...),
            ``"covis-ensemble"`` (:data:`ENSEMBLE_METHOD`; parameters ``bin_widths`` and
            ``min_co``, sequences) or ``"naive"`` (the baseline); None = the mode's default
            (:data:`DEFAULT_MODE_METHOD`: ``range-quantile`` for range, ``covis-ensemble``
            for visibility and bearing).
        anchors: anchor landmark subject numbers; None = the 4 nearest the bounding-box corners.
        out: directory for ``map.csv`` (subject, x, y of every landmark, anchors included, in
            the ground-truth frame; written atomically) and ``map.png``; None writes nothing.
        bin_width: seconds per bin; None = the mode's default (:data:`DEFAULT_BIN_WIDTH`);
            must be None for ``covis-ensemble`` (it uses ``bin_widths``); given with
            ``method=None`` in visibility/bearing mode, the ensemble's member method
            (``covis-power``) maps the run binned at that one width.
        groundtruth_fixes: ``"known"`` / ``"detect"`` / ``"none"`` (see :func:`read_run`).
        plot: write ``map.png`` (needs matplotlib) when ``out`` is given.
        **params: the masked method's parameters (e.g. ``quantile=0.95``, ``min_co=5``).
    """
    from mappers.missing import MASKED_METHODS, ensemble_embedding, masked_embedding
    from mappers.scores import mean_orientation_error, mean_position_error

    choices = [NAIVE_METHOD, ENSEMBLE_METHOD, *MASKED_METHODS]
    if method is not None and method not in choices:
        raise ValueError(f"method must be one of {choices} or None, got {method!r}")
    if mode not in MODES:
        raise ValueError(f"mode must be one of {MODES}, got {mode!r}")
    if method is None:
        method = DEFAULT_MODE_METHOD[mode]
        if method == ENSEMBLE_METHOD and bin_width is not None:
            method = ENSEMBLE_MEMBERS[0]  # one bin width asked for: one member at that width
    ensemble = method == ENSEMBLE_METHOD
    if ensemble:
        if bin_width is not None:
            raise ValueError(
                f"method {ENSEMBLE_METHOD!r} bins the run at several widths (bin_widths=...); "
                "bin_width must be None"
            )
        unknown = set(params) - {"bin_widths", "min_co", "member", "power", "angle_weight",
                                 "nearness_weight"}
        if unknown:
            raise ValueError(f"unknown parameter(s) {sorted(unknown)} for method {method!r}")
        member = params.get("member", ENSEMBLE_MEMBERS[0])
        if member not in ENSEMBLE_MEMBERS:
            raise ValueError(f"member must be one of {ENSEMBLE_MEMBERS}, got {member!r}")
        extra = {}
        if "power" in params:
            if member != "covis-power":
                raise ValueError("power applies to member='covis-power' only")
            extra["power"] = float(params["power"])
        if "angle_weight" in params:
            if member != "covis-power":
                raise ValueError("angle_weight applies to member='covis-power' only")
            extra["angle_weight"] = float(params["angle_weight"])
        nearness_weight = float(params.get("nearness_weight", 0.0))
        if nearness_weight:
            if member != "covis-power" or mode != "bearing":
                raise ValueError("nearness_weight applies to mode='bearing' with member='covis-power' only")
            extra["nearness_weight"] = nearness_weight
        widths = tuple(float(w) for w in np.atleast_1d(params.get("bin_widths", ENSEMBLE_BIN_WIDTHS)))
        min_cos = tuple(int(m) for m in np.atleast_1d(params.get("min_co", ENSEMBLE_MIN_CO)))
        if not widths or not min_cos:
            raise ValueError("bin_widths and min_co must not be empty")
        bin_width = widths[0]
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", MRCLAMDataWarning)
        history, report = load_mrclam(
            run_dir, mode, robots=robots, bin_width=bin_width, anchors=anchors,
            groundtruth_fixes=groundtruth_fixes,
        )
    msgs = list(report.warnings)
    for w in caught:  # re-issue what the loader said, so callers' filters still apply
        if not issubclass(w.category, MRCLAMDataWarning):
            warnings.warn_explicit(w.message, w.category, w.filename, w.lineno)
    for m in msgs:
        warnings.warn(m, MRCLAMDataWarning, stacklevel=2)
    subjects = np.asarray(history.meta["subjects"], dtype=np.int64)
    if method == NAIVE_METHOD:
        if params:
            raise ValueError(f"method 'naive' takes no parameters, got {sorted(params)}")
        positions = naive_map(history)
        used_method, used_params = NAIVE_METHOD, {}
    elif ensemble:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", MRCLAMDataWarning)  # already issued by load_mrclam
            run = read_run(run_dir, robots, groundtruth_fixes=groundtruth_fixes)
        if extra.get("nearness_weight"):
            # bearing parallax between images of one robot (bearings + timestamps only)
            from mappers.missing import parallax_nearness

            extra["nearness"] = parallax_nearness(
                run.obs[:, 0], run.obs[:, 1], run.obs[:, 2], run.obs[:, 4], len(run.subjects))
        hists = [(history.matrix, history.mask)]
        for w in widths[1:]:
            matrix, mask, _ = bin_run(run, mode, w)
            hists.append((matrix, mask))
        mm = ensemble_embedding(
            hists, mode, member, anchor_ids=history.anchor_ids,
            anchor_positions=history.anchor_positions,
            param_sets=[{"min_co": m, **extra} for m in min_cos],
        )
        positions, used_method = mm.positions, ENSEMBLE_METHOD
        used_params = {"bin_widths": list(widths), "min_co": list(min_cos), "member": member,
                       **({k: mm.params["members"][0][k] for k in ("power", "angle_weight",
                                                                      "nearness_weight")}
                          if member == "covis-power" else {})}
    else:
        mm = masked_embedding(
            history.matrix, history.mask, mode, method,
            anchor_ids=history.anchor_ids, anchor_positions=history.anchor_positions, **params,
        )
        positions, used_method, used_params = mm.positions, mm.method, mm.params
    if method != NAIVE_METHOD:
        for m in mm.warnings:
            _warn(f"{history.meta['run']} ({mode}, {used_method}): {m}", msgs)
    anchor_ids = history.anchor_ids
    truth = history.object_positions
    unmapped = np.flatnonzero(~np.isfinite(positions).all(axis=1))
    if unmapped.size:
        _warn(f"{history.meta['run']} ({mode}): subject(s) {subjects[unmapped].tolist()} are "
              "unmapped (empty in map.csv) and not scored", msgs)
    scored = [i for i in range(len(subjects)) if i not in set(anchor_ids.tolist())
              and np.all(np.isfinite(positions[i]))]
    exclude = [i for i in range(len(subjects)) if i not in scored]
    mpe = mean_position_error(positions, truth, exclude=exclude) if scored else float("nan")
    moe = mean_orientation_error(positions, truth, exclude=exclude) if len(scored) >= 3 else float("nan")
    centroid = np.repeat(truth[anchor_ids].mean(axis=0)[None], len(subjects), axis=0)
    centroid_mpe = mean_position_error(centroid, truth, exclude=anchor_ids.tolist())
    result = MRCLAMMap(
        run=str(history.meta["run"]), mode=mode, method=used_method, params=dict(used_params),
        subjects=subjects, positions=positions, truth=truth,
        anchor_subjects=tuple(int(s) for s in subjects[anchor_ids]), mpe=float(mpe),
        moe=float(moe), centroid_mpe=float(centroid_mpe), warnings=tuple(msgs), report=report,
        history_meta=history.meta,
    )
    if out is not None:
        out = Path(out)
        csv_path = out / "map.csv"
        _write_csv(csv_path, subjects, positions)
        png_path = None
        if plot:
            png_path = out / "map.png"
            _plot(png_path, result)
        result = MRCLAMMap(**{**result.__dict__, "csv_path": csv_path, "png_path": png_path})
    return result
