"""RANGE-3D on ``LFMDR-Camera3D-v0``: what the ranges measure and what the sightings pick (issue 34).

    python benchmarks/bench_range_3d_sides.py [--layouts 10] [--seed0 34100] [--steps 2000]
        [--range-noise 0.02] [--max-range 3.0]

The camera rides a planar robot, so every viewpoint lies on the plane ``z = camera_height``, and a
tag and its mirror image in that plane have the same range from every step
(:mod:`mappers.spatial.range_3d`). For each fresh layout this prints the map's MPE over the
non-anchor tags it placed, the *folded* MPE (each tag, estimate and truth, reflected onto the
upper side of the plane: what the ranges measure) and the share of tags more than 0.1 m off the
plane that the map puts on the wrong side, for the map and for its start (COVIS-3D's map of the
sightings, which picks the side). Medians over the layouts at the end; nothing is written.
"""

from __future__ import annotations

import sys
import warnings
from pathlib import Path

import numpy as np

import lfmdr_gym  # noqa: F401  (registers the env ids)
from lfmdr_gym import RandomWalkPolicy, collect
from mappers.spatial import Range3D

sys.path.insert(0, str(Path(__file__).resolve().parent))

from bench_camera3d import ENV_ID, layout_options, score  # noqa: E402


def layout_scores(seed: int, steps: int, range_noise: float, max_range: float) -> dict[str, float]:
    """MPE, folded MPE and wrong-side shares (map, start) of one layout's RANGE-3D map."""
    env_kw = {"sensor": "range", "range_noise": range_noise, "max_range": max_range}
    h = collect(ENV_ID, RandomWalkPolicy(), steps, seed=seed, make_kwargs=env_kw)
    height = 0.3  # the env's default camera_height: the viewpoints' plane
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        est = Range3D().fit(h.matrix, mask=h.mask, anchor_ids=h.anchor_ids,
                            anchor_positions=h.anchor_positions)
    Y, truth = est.embedding_, h.object_positions
    rest = np.setdiff1d(np.arange(h.n_objects), h.anchor_ids)
    rest = rest[np.all(np.isfinite(Y[rest]), axis=1)]

    def fold(P):
        out = P.copy()
        out[:, 2] = height + np.abs(P[:, 2] - height)
        return out

    off = rest[np.abs(truth[rest, 2] - height) > 0.1]
    side = np.sign(truth[off, 2] - height)
    return {"mpe": score(Y, truth, h.anchor_ids)[0],
            "folded": float(np.linalg.norm(fold(Y[rest]) - fold(truth[rest]), axis=1).mean()),
            "wrong_side": float(np.mean(np.sign(Y[off, 2] - height) != side)),
            "start_wrong_side": float(np.mean(np.sign(est.start_[off, 2] - height) != side))}


def main(argv: list[str] | None = None) -> None:
    ap = layout_options(__doc__, layouts=10, seed0=34100)
    ap.add_argument("--max-range", type=float, default=3.0)
    args = ap.parse_args(argv)
    rows = []
    for k in range(args.layouts):
        row = layout_scores(args.seed0 + k, args.steps, args.range_noise, args.max_range)
        rows.append(row)
        print(f"seed {args.seed0 + k}  " + "  ".join(f"{n} {v:.3f}" for n, v in row.items()),
              flush=True)
    print(f"\n{args.layouts} layouts, max_range {args.max_range} m, medians: " + "  ".join(
        f"{n} {np.median([r[n] for r in rows]):.3f}" for n in rows[0]))


if __name__ == "__main__":
    main()
