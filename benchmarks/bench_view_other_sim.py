"""VIEW-BA on histories our env cannot make: another simulator's limited-view visibility.

Our env places objects with a spacing rule, hides objects behind others and walks the robot
with its own policy; a mapper tuned on its histories can lose its margin elsewhere. This
benchmark draws histories from a different, deliberately simple world and maps them with the
masked visibility default before (``DROPOUT-BLEND``) and with ``VIEW-BA``:

- ``--objects`` objects uniform in a 2.4 m square, no spacing rule, no occlusion; four anchors
  at (+-0.9, +-0.9);
- a walk of 0.15 m steps whose heading turns by a Gaussian of 0.6 rad each step and reverses at
  the walls of a 2.3 m box;
- a camera of ``--fov`` degrees (the mask: every object inside the cone, at any distance), an
  object visible when observed and within 0.55 m.

It prints the mean non-anchor MPE [m] over the placed objects (largest run; the objects left
unmapped are counted) and the median CPU seconds per map.

    python benchmarks/bench_view_other_sim.py            # 10 layouts, seeds 0..9
"""

from __future__ import annotations

import argparse
import math
import time
import warnings

import numpy as np
from threadpoolctl import threadpool_limits

import mappers

ANCHORS = np.arange(4)


def other_sim(seed: int, n: int = 2000, m: int = 50, fov: float = 90.0, radius: float = 0.55):
    """``(objects (M, 2), X (M, N) visibility bits, mask (M, N))`` of one layout and walk."""
    rng = np.random.default_rng(seed)
    P = rng.uniform(-1.2, 1.2, (m, 2))
    P[ANCHORS] = [[-0.9, -0.9], [0.9, -0.9], [0.9, 0.9], [-0.9, 0.9]]
    C = np.zeros((n, 3))
    x, y, th = rng.uniform(-1, 1), rng.uniform(-1, 1), rng.uniform(-math.pi, math.pi)
    for t in range(n):
        th += rng.normal(0, 0.6)
        nx, ny = x + 0.15 * math.cos(th), y + 0.15 * math.sin(th)
        if abs(nx) > 1.15 or abs(ny) > 1.15:  # a wall ahead: turn back, stay
            th += math.pi
            nx, ny = x, y
        x, y = nx, ny
        C[t] = x, y, th
    rel = P[None] - C[:, None, :2]
    off = np.angle(np.exp(1j * (np.arctan2(rel[..., 1], rel[..., 0]) - C[:, 2:3])))
    mask = np.abs(off) <= math.radians(fov) / 2
    X = (mask & (np.hypot(rel[..., 0], rel[..., 1]) < radius)).astype(float)
    return P, X.T, mask.T


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--runs", type=int, default=10, help="layouts (default 10)")
    ap.add_argument("--seed", type=int, default=0, help="first seed (default 0)")
    ap.add_argument("--objects", type=int, default=50, help="objects per layout (default 50)")
    ap.add_argument("--fov", type=float, default=90.0, help="field of view [deg] (default 90)")
    args = ap.parse_args(argv)
    methods = ("DROPOUT-BLEND", "VIEW-BA")
    rows = {k: [] for k in methods}
    unmapped = dict.fromkeys(methods, 0)  # the MPE is over the placed objects
    with threadpool_limits(limits=1), warnings.catch_warnings():
        warnings.simplefilter("ignore")
        for seed in range(args.seed, args.seed + args.runs):
            P, X, mask = other_sim(seed, m=args.objects, fov=args.fov)
            keep = np.setdiff1d(np.arange(len(P)), ANCHORS)
            line = []
            for method in methods:
                t0 = time.process_time()
                m = mappers.build_map(X, ANCHORS, P[ANCHORS], method, sensor="visibility",
                                      mask=mask)
                cpu = time.process_time() - t0
                placed = keep[np.all(np.isfinite(m.positions[keep]), axis=1)]
                unmapped[method] += len(keep) - len(placed)
                rows[method].append((mappers.mean_position_error(m.positions[placed], P[placed]),
                                     cpu))
                line.append(f"{method} {rows[method][-1][0]:.4f}")
            print(f"seed {seed}: " + "  ".join(line), flush=True)
    print(f"\n{args.runs} layouts, {args.objects} objects, a {args.fov:g}-degree view, N = 2000; "
          "MPE [m] mean (largest run), CPU per map (median)")
    for method, vals in rows.items():
        a = np.array(vals)
        print(f"  {method:14s} {a[:, 0].mean():.4f} ({a[:, 0].max():.4f})  {np.median(a[:, 1]):.2f} s"
              f"  ({unmapped[method]} objects unmapped)")
    a, b = np.array(rows[methods[0]]), np.array(rows[methods[1]])
    print(f"  VIEW-BA better on {int(np.sum(b[:, 0] < a[:, 0]))} of {len(a)} layouts")


if __name__ == "__main__":
    main()
