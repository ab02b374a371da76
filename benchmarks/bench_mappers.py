"""Mapper benchmarks: time and accuracy per method, the SMACOF start, SDE against M.

Run from the project root:

    python benchmarks/bench_mappers.py              # all sections, 5 seeds
    python benchmarks/bench_mappers.py --quick      # 2 seeds, SDE at M=50,100
    python benchmarks/bench_mappers.py --sections sde --sde-sizes 50 100 200
    python benchmarks/bench_mappers.py --sections range   # UNFOLD vs SMACOF on ranges

Histories come from the simulator (``lfmdr_gym.collect`` with a random walk, M objects, N =
2000 steps) when lfmdr_gym is importable, otherwise from a numpy-only stand-in (random walk
among random objects, visibility within 0.55 m with occlusion, bearing, range). The machine is
shared: times are medians, compare ratios rather than absolute figures.
"""

from __future__ import annotations

import argparse
import statistics
import time
import warnings

import cvxpy as cp
import numpy as np
import scipy.sparse as sp
from threadpoolctl import threadpool_limits

from mappers import (
    METHODS,
    MaximumVarianceUnfolding,
    WeightedSMACOF,
    apply_affine,
    build_map,
    fit_affine,
    mean_orientation_error,
    mean_position_error,
)
from mappers.core.graph import connected_knn_graph

ENV_IDS = {"visibility": "LFMDR-Visibility-v0", "bearing": "LFMDR-Bearing-v0", "range": "LFMDR-Range-v0"}


def _synthetic(sensor: str, m: int, n_steps: int, seed: int, arena: float):
    """numpy-only stand-in for the simulator (used when lfmdr_gym is not importable)."""
    rng = np.random.default_rng(seed)
    half = arena / 2
    pts: list[np.ndarray] = []
    while len(pts) < m:
        p = rng.uniform(-half + 0.15, half - 0.15, 2)
        if all(np.hypot(*(p - q)) > 0.15 for q in pts):
            pts.append(p)
    P = np.array(pts)
    pose, poses = np.zeros(3), []
    for _ in range(n_steps):
        for attempt in range(50):
            h = pose[2] + rng.uniform(-np.pi / 4, np.pi / 4) if attempt < 10 else rng.uniform(-np.pi, np.pi)
            q = pose[:2] + 0.2 * np.array([np.cos(h), np.sin(h)])
            if np.all(np.abs(q) < half - 0.05) and np.min(np.hypot(*(P - q).T)) > 0.08:
                break
        pose = np.array([q[0], q[1], h])
        poses.append(pose)
    R = np.array(poses)
    d = P[:, None, :] - R[None, :, :2]
    dist = np.hypot(d[..., 0], d[..., 1])
    if sensor == "visibility":
        H = (dist < 0.55).astype(float)
        ang = np.arctan2(d[..., 1], d[..., 0])
        for j in range(m):  # occluded when a nearer cylinder covers the line of sight
            dang = np.abs(np.angle(np.exp(1j * (ang - ang[j]))))
            nearer = (dist < dist[j]) & (dang < np.arcsin(np.minimum(0.024 / dist, 1)))
            nearer[j] = False
            H[j, nearer.any(axis=0)] = 0
    elif sensor == "bearing":
        th = np.arctan2(d[..., 1], d[..., 0]) - R[None, :, 2]
        H = np.stack([np.cos(th), np.sin(th)], -1).reshape(m, -1)
    else:
        H = dist
    corners = np.array([[-1, -1], [1, -1], [1, 1], [-1, 1]]) * half
    anchors = np.array([np.argmin(np.hypot(*(P - c).T)) for c in corners])
    return H, P, anchors, P[anchors]


def histories(sensor: str, m: int = 50, n_steps: int = 2000, seed: int = 0):
    """(matrix, true positions, anchor ids, anchor positions, source)."""
    arena = 2.5 * np.sqrt(m / 50)  # same object density as the paper's M = 50 in 2.5 m
    try:
        from lfmdr_gym import collect
        from lfmdr_gym.exploration.random_walk import RandomWalkPolicy
    except ImportError:
        return (*_synthetic(sensor, m, n_steps, seed, arena), "synthetic")
    h = collect(
        ENV_IDS[sensor], RandomWalkPolicy(seed=seed), n_steps, seed=seed,
        make_kwargs={"n_objects": m, "arena_size": float(arena)},
    )
    return h.matrix, h.object_positions, h.anchor_ids, h.anchor_positions, "lfmdr_gym"


def _scores(positions, truth, anchors):
    keep = [i for i in range(len(truth)) if i not in set(anchors) and np.all(np.isfinite(positions[i]))]
    return (
        mean_position_error(positions[keep], truth[keep]),
        mean_orientation_error(positions[keep], truth[keep]),
    )


def bench_methods(sensors, seeds, repeats):
    for sensor in sensors:
        rows = {lab: {"t": [], "mpe": [], "moe": [], "fail": 0} for lab in METHODS}
        nine = []
        src = ""
        for seed in seeds:
            H, P, a, pa, src = histories(sensor, seed=seed)
            total = 0.0
            for lab in METHODS:
                if METHODS[lab].sensors is not None and sensor not in METHODS[lab].sensors:
                    continue  # e.g. UNFOLD maps range histories only
                times = []
                try:
                    for _ in range(repeats):
                        t0 = time.perf_counter()
                        mp = build_map(H, a, pa, lab)
                        times.append(time.perf_counter() - t0)
                except ValueError as exc:
                    rows[lab]["fail"] += 1
                    print(f"  {sensor} seed {seed} {lab}: {exc}")
                    continue
                t = statistics.median(times)
                rows[lab]["t"].append(t)
                if lab not in ("SDE",) and lab in list(METHODS)[:10]:
                    total += t
                e, o = _scores(mp.positions, P, a)
                rows[lab]["mpe"].append(e)
                rows[lab]["moe"].append(o)
            nine.append(total)
        print(f"\n## {sensor}: M=50, N=2000, {len(seeds)} layouts ({src}); defaults; MPE/MOE over non-anchors")
        print(f"{'method':12s} {'median ms':>10s} {'MPE m':>8s} {'MOE %':>8s} {'failed':>6s}")
        for lab, r in rows.items():
            if not r["t"] and not r["fail"]:
                continue  # not a method for this sensor
            if r["t"]:
                print(f"{lab:12s} {1000 * statistics.median(r['t']):10.1f} {np.mean(r['mpe']):8.3f} "
                      f"{np.mean(r['moe']):8.2f} {r['fail']:6d}")
            else:
                print(f"{lab:12s} {'-':>10s} {'-':>8s} {'-':>8s} {r['fail']:6d}")
        print(f"the nine paper methods other than SDE, together: median {1000 * statistics.median(nine):.0f} ms")


def bench_range(seeds, noises=(0.0, 0.02, 0.1)):
    """UNFOLD (the range default) against SMA(WGT) and CAL-SMA on range histories, with
    Gaussian noise of the given standard deviations [m] added to the ranges."""
    labels = ("UNFOLD", "SMA(WGT)", "CAL-SMA")
    print(f"\n## range: M=50, N=2000, {len(seeds)} layouts; defaults; MPE [m] over non-anchors"
          " (ranges + N(0, sigma^2) noise)")
    print(f"{'sigma m':>8s} " + " ".join(f"{lab:>10s}" for lab in labels)
          + f" {'UNFOLD ms':>10s}")
    for sigma in noises:
        mpe = {lab: [] for lab in labels}
        t_unfold = []
        for seed in seeds:
            H, P, a, pa, _ = histories("range", seed=seed)
            rng = np.random.default_rng(1000 + seed)
            X = np.abs(H + sigma * rng.standard_normal(H.shape)) if sigma else H
            for lab in labels:
                t0 = time.perf_counter()
                mp = build_map(X, a, pa, lab, sensor="range")
                if lab == "UNFOLD":
                    t_unfold.append(time.perf_counter() - t0)
                mpe[lab].append(_scores(mp.positions, P, a)[0])
        print(f"{sigma:8.3f} " + " ".join(f"{np.mean(mpe[lab]):10.5f}" for lab in labels)
              + f" {1000 * statistics.median(t_unfold):10.1f}")


def bench_smacof_start(seeds):
    print("\n## SMA(WGT) K=5 start on visibility histories (M=50, N=2000); MPE over non-anchors")
    starts = {
        "lpca (paper)": dict(init="lpca"),
        "unweighted (default)": dict(init="unweighted"),
        "lpca + 9 random, lowest stress": dict(init="lpca", n_init=10, random_state=0),
        "unweighted + 9 random, lowest stress": dict(init="unweighted", n_init=10, random_state=0),
    }
    res = {k: [] for k in starts}
    for seed in seeds:
        H, P, a, pa, _ = histories("visibility", seed=seed)
        keep = H.any(axis=1)
        X = H[keep] / np.linalg.norm(H[keep], axis=1, keepdims=True)
        Pk = P[keep]
        ak = np.searchsorted(np.flatnonzero(keep), a)
        for name, kw in starts.items():
            t0 = time.perf_counter()
            est = WeightedSMACOF(n_neighbors=5, **kw).fit(X)
            dt = time.perf_counter() - t0
            Y = apply_affine(est.embedding_, fit_affine(est.embedding_[ak], pa))
            e, o = _scores(Y, Pk, ak)
            res[name].append((e, o, est.stress_, dt))
    print(f"{'start':38s} {'mean MPE':>9s} {'max MPE':>8s} {'>0.5 m':>7s} {'MOE %':>7s} {'stress':>7s} {'ms':>6s}")
    for name, r in res.items():
        r = np.array(r)
        print(f"{name:38s} {r[:, 0].mean():9.3f} {r[:, 0].max():8.3f} {int((r[:, 0] > 0.5).sum()):7d} "
              f"{r[:, 1].mean():7.2f} {r[:, 2].mean():7.3f} {1000 * np.median(r[:, 3]):6.0f}")
    print("per layout MPE:", {k: [round(x[0], 3) for x in v] for k, v in res.items()})


def sde_baseline(X, k, solver="CLARABEL"):
    """The straightforward formulation: one cvxpy constraint per edge, default solver settings."""
    A, D, _ = connected_knn_graph(X, k)
    ei, ej = sp.triu(A, 1).nonzero()
    n = len(X)
    K = cp.Variable((n, n), PSD=True)
    cons = [cp.sum(K) == 0] + [
        K[i, i] + K[j, j] - 2 * K[i, j] == D[i, j] ** 2 for i, j in zip(ei, ej, strict=True)
    ]
    cp.Problem(cp.Maximize(cp.trace(K)), cons).solve(solver=solver)
    w, U = np.linalg.eigh(K.value)
    return U[:, -2:] * np.sqrt(np.clip(w[-2:], 0, None))


def bench_sde(sizes, seeds, baseline_max):
    print("\n## SDE (K=7) on visibility histories: time [s] median over layouts, MPE [m] mean "
          "(non-anchors, anchor fit)")
    variants = {
        "baseline (per-edge, CLARABEL)": lambda X: sde_baseline(X, 7),
        "ours: exact, SCS eps=1e-3 (default)": lambda X: MaximumVarianceUnfolding(n_neighbors=7).fit_transform(X),
        "ours: exact, CLARABEL": lambda X: MaximumVarianceUnfolding(n_neighbors=7, solver="CLARABEL", tol=1e-8).fit_transform(X),
        "fast MVU n_basis=20 (CLARABEL)": lambda X: MaximumVarianceUnfolding(n_neighbors=7, n_basis=20).fit_transform(X),
    }
    print(f"{'M':>4s} {'variant':38s} {'time s':>8s} {'MPE m':>7s} {'MOE %':>7s}")
    for m in sizes:
        data = []
        for seed in seeds:
            H, P, a, pa, _ = histories("visibility", m=m, seed=seed)
            keep = H.any(axis=1)
            X = H[keep] / np.linalg.norm(H[keep], axis=1, keepdims=True)
            data.append((X, P[keep], np.searchsorted(np.flatnonzero(keep), a), pa))
        base_t = None
        for name, fn in variants.items():
            if name.startswith("baseline") and m > baseline_max:
                print(f"{m:4d} {name:38s} skipped (M > --baseline-max {baseline_max}: dense KKT of "
                      f"the {m * (m + 1) // 2}-dim PSD cone)")
                continue
            if name.startswith("ours: exact, CLARABEL") and m > baseline_max:
                continue
            ts, es, os = [], [], []
            for X, P, ak, pa in data:
                t0 = time.perf_counter()
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore")
                    Y = fn(X)
                ts.append(time.perf_counter() - t0)
                e, o = _scores(apply_affine(Y, fit_affine(Y[ak], pa)), P, ak)
                es.append(e)
                os.append(o)
            t = statistics.median(ts)
            if name.startswith("baseline"):
                base_t = t
            ratio = f"  ({base_t / t:.1f}x faster than baseline)" if base_t and not name.startswith("baseline") else ""
            print(f"{m:4d} {name:38s} {t:8.2f} {np.mean(es):7.3f} {np.mean(os):7.2f}{ratio}")


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--quick", action="store_true", help="2 seeds, 1 repeat, SDE at M=50,100")
    p.add_argument("--seeds", type=int, default=5)
    p.add_argument("--repeats", type=int, default=3)
    p.add_argument("--sections", nargs="+", default=["methods", "range", "smacof", "sde"])
    p.add_argument("--sensors", nargs="+", default=["visibility", "bearing", "range"])
    p.add_argument("--sde-sizes", nargs="+", type=int, default=[50, 100, 200])
    p.add_argument("--baseline-max", type=int, default=100, help="largest M for the baseline SDE")
    args = p.parse_args()
    if args.quick:
        args.seeds, args.repeats, args.sde_sizes = 2, 1, [50, 100]
    seeds = list(range(args.seeds))
    with threadpool_limits(limits=1):  # the machine is shared; one BLAS thread is steadier
        if "methods" in args.sections:
            bench_methods(args.sensors, seeds, args.repeats)
        if "range" in args.sections:
            bench_range(seeds)
        if "smacof" in args.sections:
            bench_smacof_start(list(range(max(args.seeds, 8))))
        if "sde" in args.sections:
            bench_sde(args.sde_sizes, seeds[:3], args.baseline_max)


if __name__ == "__main__":
    main()
