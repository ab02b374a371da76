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
  pair (``iso-2nd``, :func:`mappers.spatial.sightings_median_3d.second_order_dissimilarity`);
* the maps from the sightings: COVIS-3D, the four members of COVIS-3D-MEDIAN (second-order over
  windows of 10 and 20 image pairs, geodesic, frame gap) and their median.

``--subsets``: the geometric median of every subset of one to five of seven maps (COVIS-3D, a
harmonic map, the second-order map over windows of 3, 10 and 20, the geodesic map, the frame-gap
map), ranked on eight_s3, grid_s3 and loop-2d-fast_s3 (tune) and shown on the other s3
sequences and on s1/s2 (how COVIS-3D-MEDIAN's members were chosen). The harmonic map: each tag
at the Ochiai-weighted mean of those seen with it, anchors held (one linear system; Zhu,
Ghahramani & Lafferty, ICML 2003).
The survey is read for the anchors, the scores and the oracles; never a pose column.
"""

from __future__ import annotations

import argparse
import itertools
import sys
import warnings
from pathlib import Path

import numpy as np
from scipy.sparse.csgraph import connected_components
from scipy.stats import spearmanr
from sklearn.isotonic import IsotonicRegression

from lfmdr_gym.datasets.starloc import read_starloc, scored_tags, starloc_anchors, starloc_survey
from lfmdr_gym.histories.ray_table import ray_histories
from mappers.masked import covisibility_dissimilarity, geometric_median
from mappers.smacof import weighted_smacof
from mappers.spatial import CoVisibility3D, SightingsMedian3D
from mappers.spatial.covisibility_3d import anchor_mean_start
from mappers.spatial.sightings_median_3d import (
    MIN_TARGET,
    second_order_dissimilarity,
    second_order_embedding,
)

MEMBERS = ("second-10", "second-20", "geodesic", "frame-gap")
"""COVIS-3D-MEDIAN's ``members_`` in their order (its default windows 10 and 20)."""

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
    F = second_order_dissimilarity(seen, 10)[0]
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


def harmonic_map(d: dict) -> np.ndarray:
    """The harmonic map (see the module's docstring) of the tags linked to an anchor by pairs
    seen together; NaN for the others."""
    delta, counts = covisibility_dissimilarity(d["seen"])
    np.fill_diagonal(counts, 0)
    S = np.where(counts > 0, np.exp(-delta), 0.0)
    _, label = connected_components(counts > 0, directed=False)
    keep = np.isin(label, label[d["ar"]]) & (counts.sum(axis=1) > 0)
    sub = np.flatnonzero(keep)
    loc = np.searchsorted(sub, d["ar"][keep[d["ar"]]])
    S = S[np.ix_(sub, sub)]
    L = np.diag(S.sum(axis=1)) - S
    free = np.setdiff1d(np.arange(len(sub)), loc)
    Y = np.empty((len(sub), 3))
    Y[loc] = d["apos"][keep[d["ar"]]]
    Y[free] = np.linalg.solve(L[np.ix_(free, free)], -L[np.ix_(free, loc)] @ Y[loc])
    out = np.full((len(d["seen"]), 3), np.nan)
    out[sub] = Y
    return out


def candidate_maps(d: dict) -> dict[str, np.ndarray]:
    """The seven maps the subsets are drawn from (see the module's docstring)."""
    seen, ar, apos = d["seen"], d["ar"], d["apos"]
    est = SightingsMedian3D().fit(seen.astype(float), anchor_ids=ar, anchor_positions=apos)
    maps = dict(zip(MEMBERS, est.members_, strict=True))
    maps["covis-3d"] = CoVisibility3D().fit_transform(seen.astype(float), anchor_ids=ar,
                                                      anchor_positions=apos)
    maps["harmonic"] = harmonic_map(d)
    sub = np.flatnonzero(np.isfinite(est.members_[0][:, 0]))
    maps["second-3"] = np.full((len(seen), 3), np.nan)
    maps["second-3"][sub] = second_order_embedding(seen[sub], np.searchsorted(sub, ar), apos, 3,
                                                   300)
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
    """Rank every subset of one to five maps by its mean error on :data:`TUNE` (sequences with
    fewer than two scored tags left out: loop-2d-fast_s2 has one, and COVIS-3D cannot map it)."""
    data = {name: d for name, d in data.items() if len(d["sr"]) > 1}
    maps = {name: candidate_maps(d) for name, d in data.items()}
    names = list(next(iter(maps.values())))
    s3 = [s for s in data if s.endswith("_s3")]
    rest = [s for s in data if not s.endswith("_s3")]
    rows = []
    for r in range(1, 6):
        for combo in itertools.combinations(names, r):
            e = {s: mpe(data[s], median_of([maps[s][n] for n in combo])) for s in data}
            rows.append((np.mean([e[s] for s in TUNE]),
                         np.mean([e[s] for s in s3 if s not in TUNE]),
                         np.mean([e[s] for s in rest]) if rest else np.nan, combo))
    rows.sort(key=lambda r: r[0])
    print(f"\n{len(rows)} subsets ranked on {', '.join(TUNE)} (tune), the other s3 sequences "
          "(confirm), s1/s2")
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
          f"{'iso-och':>7s} {'iso-2nd':>7s} | {'COVIS-3D':>8s} {'2nd-10':>7s} {'2nd-20':>7s} "
          f"{'geodes.':>7s} {'gap':>7s} {'MEDIAN':>7s}")
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
        members = " ".join(f"{mpe(d, m):7.2f}" for m in est.members_)
        print(f"{seq.name:16s} {g['co_median']:10.2f} {g['co_p90']:6.2f} {g['co_max']:6.2f}    "
              f"{g['spearman']:5.2f} {g['true-co']:7.2f} {g['iso-och']:7.2f} {g['iso-2nd']:7.2f} | "
              f"{mpe(d, covis):8.2f} {members} {mpe(d, est.embedding_):7.2f}", flush=True)
    if args.subsets:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            subsets(data)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
