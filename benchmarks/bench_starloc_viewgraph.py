"""STAR-loc's left camera alone: what the rays can fix, per sequence (issue 34).

    python benchmarks/bench_starloc_viewgraph.py [--sequences eight_s3,grid_s3,...] [--survey-start]

Per sequence: the image pairs (steps) by how many tags they see; the pairs of steps sharing 5
and 8 tags and the view graph's largest connected part at 8 (its steps and the scored tags it
holds); and a combinatorial bound on what resection and intersection can reach from any seed of
two steps sharing 8 tags, with pieces merged where they share 3 tags (a step is posed once it
sees 3 placed tags, a tag placed once 2 posed steps see it; no angle or noise considered, so
the bound is generous): the scored tags and the anchors of the largest such piece. A piece
must hold 3 anchors to be placed without a motion model.

``--survey-start`` (a diagnostic, never a method: it reads the survey to start the map): the
rays-only SPATIAL-BA (the benchmark's parameters) started from every tag at its surveyed
position and the steps resected to them; what the adjustment makes of the rays when the start
is perfect, a ceiling for any start. The data: ``<repo>/../shared/data/starloc``.
"""

from __future__ import annotations

import argparse
import warnings
from pathlib import Path

import numpy as np
from scipy import sparse
from scipy.sparse.csgraph import connected_components

from lfmdr_gym.datasets.starloc import read_starloc, scored_tags, starloc_anchors, starloc_survey
from lfmdr_gym.experiments.starloc import STARLOC_PARAMS
from lfmdr_gym.histories.ray_table import ray_histories
from mappers.spatial import SpatialAdjustment
from mappers.spatial.registration import register_rays

ROOT = Path(__file__).resolve().parents[1]
DATA = ROOT.parent / "shared" / "data" / "starloc" / "data"


def _closure(V, tags, steps):
    """Tags and steps reached from ``tags``/``steps`` (bool) by posing steps that see 3 placed
    tags and placing tags 2 posed steps see (``V``: steps x tags, bool)."""
    while True:
        new_steps = steps | (V.astype(int) @ tags.astype(int) >= 3)
        new_tags = tags | (V.T.astype(int) @ new_steps.astype(int) >= 2)
        if (new_steps == steps).all() and (new_tags == tags).all():
            return tags, steps
        tags, steps = new_tags, new_steps


def reach(V, min_seed: int = 8):
    """The pieces (bool tag masks) grown from every seed pair sharing ``min_seed`` tags, merged
    where they share 3 tags and grown again, largest first."""
    n = V.shape[0]
    S = V.astype(int) @ V.T.astype(int)
    np.fill_diagonal(S, 0)
    pieces, seen = [], set()
    for a, b in zip(*np.nonzero(np.triu(S >= min_seed)), strict=True):
        steps = np.zeros(n, dtype=bool)
        steps[[a, b]] = True
        tags, _ = _closure(V, V[a] & V[b], steps)
        if tags.tobytes() not in seen:
            seen.add(tags.tobytes())
            pieces.append(tags)
    merged = True
    while merged:
        merged = False
        pieces.sort(key=lambda t: -int(t.sum()))
        out = []
        while pieces:
            t = pieces.pop(0)
            for k, u in enumerate(pieces):
                if (t & u).sum() >= 3:
                    t = _closure(V, t | pieces.pop(k), np.zeros(n, dtype=bool))[0]
                    merged = True
                    break
            out.append(t)
        pieces = out
    return sorted(pieces, key=lambda t: -int(t.sum()))


def survey_start(seq: Path) -> tuple[float, float]:
    """(MPE, mapped) of the rays-only map started at the survey (see the module's docstring)."""
    table, survey = read_starloc(seq, "bearing"), starloc_survey(seq)
    anchors = starloc_anchors(table, survey)
    scored = scored_tags(table, survey, anchors)
    h = ray_histories(table)
    row = {int(t): k for k, t in enumerate(h.ids)}
    xyz = survey.set_index("landmark")[["x", "y", "z"]]
    truth = xyz.reindex([int(t) for t in h.ids]).to_numpy(dtype=float)  # NaN: not surveyed
    start = SpatialAdjustment._rays_start

    def from_survey(obs, ids, pos, how, noise):
        known = np.flatnonzero(np.isfinite(truth[:, 0]))
        _, R, C = register_rays(obs, known, truth[known], rounds=1)
        return truth.copy(), R, C

    SpatialAdjustment._rays_start = staticmethod(from_survey)
    try:
        est = SpatialAdjustment(**STARLOC_PARAMS["bearing"])
        Y = est.fit_transform(h.rays, anchor_ids=[row[a] for a in anchors],
                              anchor_positions=xyz.loc[anchors].to_numpy(dtype=float))
    finally:
        SpatialAdjustment._rays_start = start
    placed = [t for t in scored if np.isfinite(Y[row[t], 0])]
    err = [np.linalg.norm(Y[row[t]] - truth[row[t]]) for t in placed]
    return float(np.mean(err)), len(placed) / len(scored)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sequences", default="eight_s3,grid_s3,loop-2d-fast_s3,loop-2d_s3,"
                                            "loop-3d_s3,zigzag_s3")
    ap.add_argument("--data", type=Path, default=DATA)
    ap.add_argument("--survey-start", action="store_true")
    args = ap.parse_args(argv)
    print(f"{'sequence':16s} {'steps':>5s} {'<=2 tags':>8s} {'pairs>=5':>8s} {'pairs>=8':>8s} "
          f"{'part@8':>7s} {'scored':>7s} {'bound scored':>12s} {'anchors':>7s}"
          + ("  survey start" if args.survey_start else ""))
    for name in [s for s in args.sequences.split(",") if s]:
        seq = args.data / name
        table, survey = read_starloc(seq, "visibility"), starloc_survey(seq)
        anchors = starloc_anchors(table, survey)
        scored = scored_tags(table, survey, anchors)
        h = ray_histories(table)
        row = {int(t): k for k, t in enumerate(h.ids)}
        V = h.visibility.T > 0  # steps x tags
        sr = np.array([row[t] for t in scored])
        ar = np.array([row[a] for a in anchors])
        S = V.astype(int) @ V.T.astype(int)
        np.fill_diagonal(S, 0)
        iu = np.triu_indices(len(V), 1)
        _, label = connected_components(sparse.csr_matrix(S >= 8), directed=False)
        size = np.bincount(label)
        part = label == np.argmax(size)
        part_tags = V[part].any(axis=0)
        pieces = reach(V)
        best = pieces[0] if pieces else np.zeros(V.shape[1], dtype=bool)
        line = (f"{name:16s} {len(V):5d} {int((V.sum(1) <= 2).sum()):8d} "
                f"{int((S[iu] >= 5).sum()):8d} {int((S[iu] >= 8).sum()):8d} "
                f"{int(part.sum()):7d} {int(part_tags[sr].sum()):3d}/{len(sr):<3d} "
                f"{int(best[sr].sum()):8d}/{len(sr):<3d} {int(best[ar].sum()):7d}")
        if args.survey_start:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                mpe, mapped = survey_start(seq)
            line += f"  {mpe:.3f} m, {mapped:.0%}"
        print(line, flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
