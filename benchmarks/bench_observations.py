"""Observation table -> History at scale (issue 33): a 1,000,000-row log in under 5 s, one core.

A synthetic log of ``--robots`` robots driving among ``--landmarks`` landmarks: each camera frame
(10 Hz per robot) sights a few landmarks with range and bearing. It times, as medians over
``--repeats`` runs on one BLAS/OpenMP thread:

- ``observations_to_history`` from the DataFrame (checks included), unbinned (one step per
  frame) and binned (``--bin`` seconds), for range-bearing (the fused history) and visibility,
  and with string ids;
- reading the log from Parquet and from CSV (``read_observations``), for reference.

    python benchmarks/bench_observations.py                  # 1,000,000 rows, 200 landmarks
    python benchmarks/bench_observations.py --rows 200000 --repeats 3
"""

from __future__ import annotations

import argparse
import statistics
import tempfile
import time
from pathlib import Path

import numpy as np
import pandas as pd
from threadpoolctl import threadpool_limits

from lfmdr_gym.histories.observation_table import read_observations, write_observations
from lfmdr_gym.histories.observations import observations_to_history

GOAL_SECONDS = 5.0  # a 1,000,000-row table -> History, one core


def synthetic_log(rows: int, landmarks: int, robots: int, seed: int = 0) -> tuple[pd.DataFrame,
                                                                                  pd.DataFrame]:
    """(observations, anchors): ``rows`` sightings, 4 per frame, 10 frames/s per robot."""
    rng = np.random.default_rng(seed)
    per_frame = 4
    frames = rows // per_frame
    robot = rng.integers(0, robots, frames)
    frame = np.zeros(frames, np.int64)
    for r in range(robots):  # frame numbers per robot (setup only, not timed)
        sel = robot == r
        frame[sel] = np.arange(sel.sum())
    table = pd.DataFrame({
        "time": np.repeat(frame * 0.1 + robot * 0.013, per_frame),
        "robot": np.repeat(robot, per_frame),
        "frame": np.repeat(frame, per_frame),
        # 4 distinct landmarks a frame: a random one and three at fixed offsets from it
        "landmark": ((rng.integers(0, landmarks, frames)[:, None] + [0, 7, 31, 97])
                     % landmarks).ravel(),
        "range": rng.uniform(0.3, 6.0, frames * per_frame),
        "bearing": rng.uniform(-0.6, 0.6, frames * per_frame),
    })
    xy = rng.uniform(-10, 10, (landmarks, 2))
    anchors = pd.DataFrame({"landmark": [0, 1, 2, 3], "x": xy[:4, 0], "y": xy[:4, 1]})
    anchors.loc[:, ["x", "y"]] = [[-10, -10], [10, -10], [10, 10], [-10, 10]]
    return table, anchors


def median_time(fn, repeats: int) -> float:
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return statistics.median(times)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rows", type=int, default=1_000_000)
    ap.add_argument("--landmarks", type=int, default=200)
    ap.add_argument("--robots", type=int, default=5)
    ap.add_argument("--bin", type=float, default=0.5, help="bin width [s] of the binned case")
    ap.add_argument("--repeats", type=int, default=5)
    args = ap.parse_args()
    table, anchors = synthetic_log(args.rows, args.landmarks, args.robots)
    print(f"log: {len(table):,} rows, {args.landmarks} landmarks, {args.robots} robots, "
          f"{table.groupby(['robot', 'frame']).ngroups:,} frames")
    results = {}
    with threadpool_limits(1):
        cases = {
            "range-bearing, one step per frame": dict(sensor="range-bearing"),
            f"range-bearing, {args.bin} s bins": dict(sensor="range-bearing", bin_width=args.bin),
            "visibility, one step per frame": dict(sensor="visibility"),
        }
        # the same log with string ids ("tag-7", "bot2"), as a tag detector names them
        named = table.assign(landmark="tag-" + table["landmark"].astype(str),
                             robot="bot" + table["robot"].astype(str))
        named_anchors = anchors.assign(landmark="tag-" + anchors["landmark"].astype(str))
        cases["range-bearing, string ids, per frame"] = dict(sensor="range-bearing", named=True)
        for name, kw in cases.items():
            log, anc = (named, named_anchors) if kw.pop("named", False) else (table, anchors)
            hist = observations_to_history(log, anc, **kw)
            results[name] = median_time(
                lambda kw=kw, log=log, anc=anc: observations_to_history(log, anc, **kw),
                args.repeats)
            part = hist.parts["range"] if hist.fused else hist
            print(f"  table -> History  {name:<38} {results[name]:6.2f} s  "
                  f"({hist.n_objects} x {hist.n_steps:,} steps, sparse: {part.is_sparse})")
        with tempfile.TemporaryDirectory() as tmp:
            for suffix in (".parquet", ".csv"):
                path = write_observations(table, Path(tmp) / f"log{suffix}")
                t = median_time(lambda path=path: read_observations(path), max(1, args.repeats // 2))
                print(f"  read_observations {suffix:<38} {t:6.2f} s  "
                      f"({path.stat().st_size / 2**20:.0f} MiB)")
    worst = max(results.values())
    verdict = "meets" if worst < GOAL_SECONDS else "MISSES"
    print(f"goal: {len(table):,}-row table -> History in < {GOAL_SECONDS:g} s on one core: "
          f"slowest case {worst:.2f} s ({verdict})")


if __name__ == "__main__":
    main()
