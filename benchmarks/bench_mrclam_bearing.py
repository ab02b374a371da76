"""MRCLAM: what bearings add to the pattern of what was seen (diagnostics, not a mapper).

    python benchmarks/bench_mrclam_bearing.py [--data DIR]

Why the bearing default of ``lfmdr mrclam`` is the covisibility ensemble (the same map as
visibility): each diagnostic below measures one way bearings could carry map information
without a pose or a motion model, per run. Ground truth is used to *score* the diagnostics only.

1. ``wide``: chaining the relative bearings of one robot's consecutive images through the
   landmarks they share (5 s windows) could widen the +-33 deg field of view. Fraction of the
   chained pairs farther apart than the field of view (1.22 rad).
2. Spearman correlation with the true distance over pairs seen together (>= 5 times):
   ``covis`` = -log co-observation rate (Ochiai, 2 s bins; what the ensemble uses),
   ``angle`` = mean subtended angle in the images that saw both,
   ``align`` = -log rate of seeing the pair within 0.3 rad of each other given one of them
   (a uniform-viewpoint argument makes it ~ 1 / distance).
3. Weak perspective: if the landmarks seen together are far compared with their spread, one
   image's bearings are an affine function of the positions, ``b_k ~ a + g . x_k``, and the
   bearing matrix of images with >= 4 landmarks is rank 2 after centring per image (a PCA with
   missing data, the paper's recipe). ``affine`` = MPE of that model's least-squares fixed point
   with the 4 anchors fixed, iterated *from the ground truth* (alternating least squares, 300
   sweeps, 0.25 s bins): small if the model holds. ``triple`` = Spearman between log |z| from
   image ratios (b_i - b_j) / (b_j - b_k) (Cauchy median, uniform viewing directions) and
   the true side ratio |x_i - x_j| / |x_j - x_k|, over triples seen >= 15 times.

Measured (2026-11, this script, ~30 s): ``wide`` 0-0.13 %; Spearman covis 0.82-0.92, angle
-0.01-0.38 and align 0.58-0.72 on DS1-3 (0.92 and 0.87 on DS6); ``affine`` 1.05-2.05 m on DS1-3
(the model does not hold: ranges of 1-5 m against spreads of 2-4 m) but 0.09 m on DS6 (two
tight clusters seen from afar); ``triple`` 0.11-0.35 on DS1-3, 0.95 on DS6. So on the spread-out
layouts bearings from unknown viewpoints add little that a pose-free statistic can use: an
image with m landmarks constrains the map only through the m - 3 numbers left after its
viewpoint and heading, and using those means solving for the viewpoint (localisation).
"""

from __future__ import annotations

import argparse
import itertools
import time
import warnings
from pathlib import Path

import numpy as np
from scipy.stats import spearmanr

from lfmdr_gym.datasets.mrclam import MRCLAMDataWarning, bin_run, image_pairs, read_run

FOV = 0.61  # |bearing| <= 0.61 rad in MRCLAM


def _images(run):
    """(landmarks, bearings, robot, time) per camera image, in time order per robot."""
    order = np.lexsort((run.obs[:, 2], run.image))
    obs, img = run.obs[order], run.image[order]
    starts = np.flatnonzero(np.r_[True, img[1:] != img[:-1]])
    out = [(o[:, 2].astype(int), o[:, 4], o[0, 0], o[0, 1]) for o in np.split(obs, starts[1:])]
    return sorted(out, key=lambda x: (x[2], x[3]))


def wide_fraction(run, window: float = 5.0) -> float:
    """Fraction of landmark pairs chained across consecutive images (one robot, one window)
    whose relative bearing exceeds the field of view."""
    wide = total = 0
    chain: dict[int, float] = {}
    prev: dict[int, float] = {}
    key = None

    def flush():
        nonlocal wide, total
        az = np.array(list(chain.values()))
        if len(az) > 1:
            rel = np.abs(np.angle(np.exp(1j * (az[:, None] - az[None]))))[np.triu_indices(len(az), 1)]
            wide += int(np.sum(rel > 2 * FOV))
            total += len(rel)

    for lms, brg, robot, t in _images(run):
        k = (robot, int(np.floor((t - run.t0) / window)))
        shared = [m for m in lms if m in prev]
        if k != key or not shared:
            flush()
            chain, offset, key = {}, 0.0, k
        else:
            offset = float(np.mean([prev[m] - b for m, b in zip(lms, brg, strict=True) if m in prev]))
        prev = {int(m): float(b) + offset for m, b in zip(lms, brg, strict=True)}
        for m, b in prev.items():
            chain.setdefault(m, b)
    flush()
    return wide / max(total, 1)


def pair_correlations(run, min_seen: int = 5, x: float = 0.3) -> tuple[float, float, float]:
    M = len(run.subjects)
    D = np.linalg.norm(run.truth[:, None] - run.truth[None], axis=2)
    seen = bin_run(run, "visibility", 2.0)[0] > 0
    C = seen.astype(float) @ seen.T.astype(float)
    P = image_pairs(run)
    i, j, alpha = P[:, 0].astype(int), P[:, 1].astype(int), np.abs(P[:, 4] - P[:, 5])
    trials, hits = np.zeros(M), np.zeros((M, M))
    for lms, brg, _, _ in _images(run):
        for a in np.flatnonzero(np.abs(brg) <= FOV - x):
            trials[lms[a]] += 1
            near = (np.abs(brg - brg[a]) <= x) & (lms != lms[a])
            hits[lms[a], lms[near]] += 1
    q = np.sqrt((hits / np.maximum(trials[:, None], 1)) * (hits / np.maximum(trials[:, None], 1)).T)
    rows = []
    for a, b in itertools.combinations(range(M), 2):
        s = (i == a) & (j == b)
        if C[a, b] >= min_seen and s.sum() >= min_seen and q[a, b] > 0:
            rows.append((D[a, b], -np.log(C[a, b] / np.sqrt(C[a, a] * C[b, b])),
                         alpha[s].mean(), -np.log(q[a, b])))
    d, covis, angle, align = np.array(rows).T
    return (spearmanr(d, covis)[0], spearmanr(d, angle)[0], spearmanr(d, align)[0])


def affine_fixed_point(run, anchors: np.ndarray, width: float = 0.25, sweeps: int = 300) -> float:
    """MPE of the weak-perspective (rank-2 after centring) model fitted from the truth."""
    M = len(run.subjects)
    matrix, mask, _, _ = bin_run(run, "bearing", width)  # per-robot bins, circular-mean bearing
    seen = mask[:, 0::2]
    angle = np.arctan2(matrix[:, 1::2], matrix[:, 0::2])
    # 3 unknowns per bin: fewer than 4 landmarks constrain nothing
    cols = [(np.flatnonzero(seen[:, t]), angle[seen[:, t], t])
            for t in np.flatnonzero(seen.sum(axis=0) >= 4)]
    X = run.truth.copy()
    free = np.setdiff1d(np.arange(M), anchors)
    for _ in range(sweeps):
        AtA, Atb = np.zeros((M, 2, 2)), np.zeros((M, 2))
        for lms, v in cols:
            A = np.column_stack([np.ones(len(lms)), X[lms]])
            p = np.linalg.solve(A.T @ A + 1e-9 * np.eye(3), A.T @ v)
            AtA[lms] += np.outer(p[1:], p[1:])
            Atb[lms] += p[1:][None, :] * (v - p[0])[:, None]
        for k in free:
            if np.linalg.det(AtA[k]) > 1e-12:
                X[k] = np.linalg.solve(AtA[k], Atb[k])
    return float(np.linalg.norm(X[free] - run.truth[free], axis=1).mean())


def triple_correlation(run, min_seen: int = 15) -> float:
    ratios: dict[tuple[int, int, int], list[float]] = {}
    for lms, brg, _, _ in _images(run):
        for a, b, c in itertools.combinations(range(len(lms)), 3):
            if abs(brg[b] - brg[c]) > 1e-3:
                ratios.setdefault((lms[a], lms[b], lms[c]), []).append(
                    (brg[a] - brg[b]) / (brg[b] - brg[c]))
    est, true = [], []
    for (i, j, k), v in ratios.items():
        if len(v) >= min_seen:
            q1, med, q3 = np.percentile(v, [25, 50, 75])
            est.append(abs(complex(med, (q3 - q1) / 2)))
            t = run.truth
            true.append(np.linalg.norm(t[i] - t[j]) / np.linalg.norm(t[j] - t[k]))
    return float(spearmanr(np.log(est), np.log(true))[0])


def main(argv: list[str] | None = None) -> None:
    here = Path(__file__).resolve().parents[1]
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--data", type=Path, default=here.parent / "shared" / "data" / "mrclam")
    args = ap.parse_args(argv)
    runs = sorted(p for p in args.data.glob("MRCLAM_Dataset*") if p.is_dir())
    if not runs:
        raise SystemExit(f"no MRCLAM_Dataset* directories under {args.data}")
    from lfmdr_gym.datasets.mrclam import corner_anchors

    t0 = time.perf_counter()
    print(f"{'run':<16}{'wide %':>8}{'covis':>8}{'angle':>8}{'align':>8}{'affine m':>10}{'triple':>8}")
    for path in runs:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", MRCLAMDataWarning)
            run = read_run(path)
        anchors = corner_anchors(run.truth)
        rc, ra, rq = pair_correlations(run)
        print(f"{run.name:<16}{100 * wide_fraction(run):>8.2f}{rc:>8.2f}{ra:>8.2f}{rq:>8.2f}"
              f"{affine_fixed_point(run, anchors):>10.2f}{triple_correlation(run):>8.2f}", flush=True)
    print(f"[{time.perf_counter() - t0:.0f} s]")


if __name__ == "__main__":
    main()
