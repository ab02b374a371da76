"""STAR-loc from the sightings alone: why co-observation maps stay near 2 m (issue 34).

    python benchmarks/bench_starloc_sightings.py [--data DIR] [--setups s3] [--subsets]

Per sequence (anchors and scored tags as in ``bench_starloc.py``; non-anchor MPE [m], the tags
never placed left out):

* the pairs seen in one image pair: how far apart they truly are (median, 90th percentile,
  largest), and the rank correlation of their ``-log`` Ochiai coefficient with that distance;
* three *oracle* maps, weighted SMACOF with the anchors held from COVIS-3D's start, that read the
  survey for their targets (a diagnosis, never a method): the true distances of the pairs seen
  together only (``true-co``); the best monotone function, fitted on the truth, of the ``-log``
  Ochiai coefficient of those pairs (``iso-och``) and of the second-order dissimilarity of every
  pair (``iso-2nd``, :func:`mappers.spatial.sightings_median_3d.second_order_embedding`'s);
* the maps from the sightings: COVIS-3D, the three members of COVIS-3D-MEDIAN (harmonic,
  second-order over windows of 10 image pairs, geodesic) and their median.

``--subsets``: the geometric median of every subset of one to five of seven maps (COVIS-3D, the
harmonic map, the second-order map over windows of 3, 10 and 20, the geodesic map, and a map of
the log frame gaps between two tags' sightings), ranked on eight_s3, grid_s3 and loop-2d-fast_s3
and shown on the other s3 sequences and on s1/s2 (the choice of COVIS-3D-MEDIAN's members).
The survey is read for the anchors, the scores and the oracles; never a pose column.
"""

from __future__ import annotations

import argparse
import itertools
import sys
import warnings
from pathlib import Path

import numpy as np
from scipy.stats import spearmanr
from sklearn.isotonic import IsotonicRegression

from lfmdr_gym.datasets.starloc import read_starloc, scored_tags, starloc_anchors, starloc_survey
from lfmdr_gym.histories.ray_table import ray_histories
from mappers.masked import covisibility_dissimilarity, geometric_median
from mappers.smacof import weighted_smacof
from mappers.spatial import CoVisibility3D, SightingsMedian3D
from mappers.spatial.covisibility_3d import anchor_mean_start, anchor_scale
from mappers.spatial.sightings_median_3d import (
    MIN_TARGET,
    second_order_embedding,
    window_sightings,
)

ROOT = Path(__file__).resolve().parents[1]
DEFAULT_DATA = ROOT.parent / "shared" / "data" / "starloc"
TUNE = ("eight_s3", "grid_s3", "loop-2d-fast_s3")


def load(seq: Path) -> dict:
    """The sightings (M, N) in time order, anchor rows and positions, scored rows, the survey's
    positions of every tag (for scoring and the oracles only)."""
    table = read_starloc(seq, "visibility")
    survey = starloc_survey(seq)
    anchors = starloc_anchors(table, survey)
    scored = scored_tags(table, survey, anchors)
    h = ray_histories(table)
    row = {int(t): k for k, t in enumerate(h.ids)}
    xyz = survey.set_index("landmark").loc[h.ids, ["x", "y", "z"]].to_numpy(dtype=float)
    ar = np.array([row[a] for a in anchors])
    return {"seen": h.visibility > 0, "ar": ar, "apos": xyz[ar],
            "sr": np.array([row[t] for t in scored]), "xyz": xyz}


def mpe(d: dict, P: np.ndarray) -> float:
    """Mean error of the scored tags the map placed."""
    E, T = P[d["sr"]], d["xyz"][d["sr"]]
    ok = np.all(np.isfinite(E), axis=1)
    return float(np.linalg.norm(E[ok] - T[ok], axis=1).mean()) if ok.any() else float("nan")


def oracle_map(d: dict, targets: np.ndarray, weights: np.ndarray) -> np.ndarray:
    """Weighted SMACOF of ``targets`` with the anchors held, from COVIS-3D's start, on the
    tags seen with another."""
    delta, counts = covisibility_dissimilarity(d["seen"])
    np.fill_diagonal(counts, 0)
    sub = np.flatnonzero(counts.sum(axis=1) > 0)
    loc = np.searchsorted(sub, d["ar"])
    och = np.where(counts > 0, np.exp(-delta), 0.0)[np.ix_(sub, sub)]
    W = weights[np.ix_(sub, sub)].copy()
    np.fill_diagonal(W, 0.0)
    Y, _, _ = weighted_smacof(targets[np.ix_(sub, sub)], W, anchor_mean_start(och, loc, d["apos"]),
                              fixed=loc, fixed_positions=d["apos"], max_iter=300)
    out = np.full((len(d["xyz"]), 3), np.nan)
    out[sub] = Y
    return out


def second_order(seen: np.ndarray, window: int) -> np.ndarray:
    """The second-order dissimilarity of :func:`second_order_embedding` (its formula)."""
    delta, counts = covisibility_dissimilarity(window_sightings(seen, window))
    och = np.exp(-delta) * (counts > 0)
    np.fill_diagonal(och, 1.0)
    rows = och / np.linalg.norm(och, axis=1, keepdims=True)
    return np.clip(1.0 - rows @ rows.T, 0.0, None)


def diagnosis(d: dict) -> dict:
    """The distances of the pairs seen together and the three oracles' errors."""
    seen, X = d["seen"], d["xyz"]
    delta, counts = covisibility_dissimilarity(seen)
    np.fill_diagonal(counts, 0)
    truth = np.linalg.norm(X[:, None] - X[None], axis=2)
    iu = np.triu_indices(len(X), 1)
    co = counts[iu] > 0
    iso = IsotonicRegression().fit(delta[iu][co], truth[iu][co])
    T_och = np.zeros_like(truth)
    T_och[counts > 0] = iso.predict(delta[counts > 0])
    F = second_order(seen, 10)
    iso2 = IsotonicRegression().fit(F[iu], truth[iu])
    T_2nd = np.zeros_like(truth)
    T_2nd[iu] = iso2.predict(F[iu])
    T_2nd = T_2nd + T_2nd.T
    return {"co_median": np.median(truth[iu][co]), "co_p90": np.percentile(truth[iu][co], 90),
            "co_max": truth[iu][co].max(),
            "spearman": spearmanr(delta[iu][co], truth[iu][co])[0],
            "true-co": mpe(d, oracle_map(d, truth, (counts > 0).astype(float))),
            "iso-och": mpe(d, oracle_map(d, T_och, np.sqrt(counts))),
            "iso-2nd": mpe(d, oracle_map(d, T_2nd, 1.0 / np.maximum(T_2nd, MIN_TARGET) ** 2))}


def frame_gap_map(d: dict) -> np.ndarray:
    """Targets: the mean log(1 + frame gap) from each sighting of one tag to the nearest of the
    other's (the smaller of the two directions), scaled on the anchors; Sammon weights."""
    seen = d["seen"]
    delta, counts = covisibility_dissimilarity(seen)
    np.fill_diagonal(counts, 0)
    sub = np.flatnonzero(counts.sum(axis=1) > 0)
    loc = np.searchsorted(sub, d["ar"])
    cols = [np.flatnonzero(seen[i]) for i in sub]
    G = np.array([[np.mean(np.log1p(np.min(np.abs(a[:, None] - b[None]), axis=1))) for b in cols]
                  for a in cols])
    G = np.minimum(G, G.T)
    np.fill_diagonal(G, 0.0)
    T = anchor_scale(G, loc, d["apos"]) * G
    W = 1.0 / np.maximum(T, MIN_TARGET) ** 2
    np.fill_diagonal(W, 0.0)
    och = np.where(counts > 0, np.exp(-delta), 0.0)[np.ix_(sub, sub)]
    Y, _, _ = weighted_smacof(T, W, anchor_mean_start(och, loc, d["apos"]), fixed=loc,
                              fixed_positions=d["apos"], max_iter=300)
    out = np.full((len(seen), 3), np.nan)
    out[sub] = Y
    return out


def candidate_maps(d: dict) -> dict[str, np.ndarray]:
    """The seven maps the subsets are drawn from (see the module's docstring)."""
    seen, ar, apos = d["seen"], d["ar"], d["apos"]
    est = SightingsMedian3D().fit(seen.astype(float), anchor_ids=ar, anchor_positions=apos)
    maps = {"covis-3d": CoVisibility3D().fit_transform(seen.astype(float), anchor_ids=ar,
                                                       anchor_positions=apos),
            "harmonic": est.members_[0], "second-10": est.members_[1],
            "geodesic": est.members_[2], "frame-gap": frame_gap_map(d)}
    for w in (3, 20):
        sub = np.flatnonzero(np.isfinite(est.members_[1][:, 0]))
        out = np.full((len(seen), 3), np.nan)
        out[sub] = second_order_embedding(seen[sub], np.searchsorted(sub, ar), apos, w, 300)
        maps[f"second-{w}"] = out
    return maps


def median_of(maps: list[np.ndarray]) -> np.ndarray:
    """Each tag at the geometric median of the maps that placed it."""
    P = np.stack(maps)
    out = np.full(P.shape[1:], np.nan)
    placed = np.isfinite(P[:, :, 0])
    for which in np.unique(placed, axis=1).T:
        rows = np.flatnonzero(np.all(placed == which[:, None], axis=0))
        if which.any():
            out[rows] = geometric_median(P[which][:, rows])
    return out


def subsets(data: dict[str, dict]) -> None:
    """Rank every subset of one to five maps by its mean error on :data:`TUNE`."""
    maps = {name: candidate_maps(d) for name, d in data.items()}
    names = list(next(iter(maps.values())))
    s3 = [s for s in data if s.endswith("_s3")]
    rest = [s for s in data if not s.endswith("_s3") and len(data[s]["sr"]) > 1]
    rows = []
    for r in range(1, 6):
        for combo in itertools.combinations(names, r):
            e = {s: mpe(data[s], median_of([maps[s][n] for n in combo])) for s in data}
            rows.append((np.mean([e[s] for s in TUNE]),
                         np.mean([e[s] for s in s3 if s not in TUNE]),
                         np.mean([e[s] for s in rest]) if rest else np.nan, combo))
    rows.sort(key=lambda r: r[0])
    print(f"\n{len(rows)} subsets ranked on {', '.join(TUNE)}; the other s3 sequences; s1/s2 "
          "(sequences with more than one scored tag)")
    base = next(r for r in rows if r[3] == ("covis-3d",))
    for r in [*rows[:8], base]:
        print(f"  tune {r[0]:.3f}  confirm {r[1]:.3f}  s1/s2 {r[2]:.3f}  {' + '.join(r[3])}")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", type=Path, default=DEFAULT_DATA)
    parser.add_argument("--setups", default="s3", help="comma-separated, e.g. s1,s2,s3")
    parser.add_argument("--subsets", action="store_true",
                        help="rank the medians of subsets of seven maps (every setup is loaded)")
    args = parser.parse_args(argv)
    folders = sorted(p for p in (args.data / "data").iterdir() if p.is_dir()) \
        if (args.data / "data").is_dir() else []
    if not folders:
        print(f"no STAR-loc sequences under {args.data / 'data'}", file=sys.stderr)
        return 1
    setups = set(args.setups.split(","))
    print(f"{'sequence':16s} {'co-seen median/p90/max [m]':>26s} {'rho':>5s} {'true-co':>7s} "
          f"{'iso-och':>7s} {'iso-2nd':>7s} | {'COVIS-3D':>8s} {'harmon.':>7s} {'2nd-10':>7s} "
          f"{'geodes.':>7s} {'MEDIAN':>7s}")
    data = {}
    for seq in folders:
        d = load(seq)
        if seq.name.rsplit("_", 1)[-1] not in setups and not args.subsets:
            continue
        data[seq.name] = d
        if seq.name.rsplit("_", 1)[-1] not in setups or len(d["sr"]) < 2:
            continue
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            g = diagnosis(d)
            est = SightingsMedian3D().fit(d["seen"].astype(float), anchor_ids=d["ar"],
                                          anchor_positions=d["apos"])
            covis = CoVisibility3D().fit_transform(d["seen"].astype(float), anchor_ids=d["ar"],
                                                   anchor_positions=d["apos"])
        members = [mpe(d, m) for m in est.members_]
        print(f"{seq.name:16s} {g['co_median']:10.2f} {g['co_p90']:6.2f} {g['co_max']:6.2f}    "
              f"{g['spearman']:5.2f} {g['true-co']:7.2f} {g['iso-och']:7.2f} {g['iso-2nd']:7.2f} | "
              f"{mpe(d, covis):8.2f} {members[0]:7.2f} {members[1]:7.2f} {members[2]:7.2f} "
              f"{mpe(d, est.embedding_):7.2f}", flush=True)
    if args.subsets:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            subsets(data)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
