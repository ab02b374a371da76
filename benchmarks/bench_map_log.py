"""``lfmdr map LOG`` on a large observation log: 200 landmarks, 1,000,000 sightings (issue 33's
goal: under a minute, end to end: read, check, bin, map, write).

The log is simulated here with numpy alone, as a user's robot would log it: one robot on a
smooth random walk through a 30 m x 30 m hall of 200 landmarks, a camera with a 120 degree view
and 6 m of range at 10 frames per second; each sighting a row ``time, landmark, bearing,
range`` (2 degrees and 2 cm of noise), landmark ids strings ("tag_17"). Four landmarks near the
corners are the anchors; the truth scores the map. The log is written as Parquet (``--csv``:
CSV) outside the timing, then the command is run in a fresh process and timed as a user would
see it.

    python benchmarks/bench_map_log.py                        # 1,000,000 rows, range
    python benchmarks/bench_map_log.py --rows 200000 --sensor bearing --bin 1
    python benchmarks/bench_map_log.py --repeat 3             # median of 3 runs

Prints the rows, landmarks and frames of the log, the command, its wall time (median over
``--repeat``) and the map's scores.
"""

from __future__ import annotations

import argparse
import json
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import pandas as pd

ROOT = Path(__file__).resolve().parent.parent
GOAL_SECONDS = 60.0


def simulate_log(rows: int, landmarks: int = 200, *, side: float = 30.0, fov_deg: float = 120.0,
                 max_range: float = 6.0, rate_hz: float = 10.0, bearing_sd_deg: float = 2.0,
                 range_sd: float = 0.02, seed: int = 0) -> tuple[pd.DataFrame, pd.DataFrame]:
    """(log, truth): about ``rows`` sightings of a robot's camera, and the landmarks' positions.

    The robot's heading turns by a random amount each frame (a smooth walk) and turns back from
    the walls; a landmark is sighted when it is within ``max_range`` and ``fov_deg`` of the
    heading. Frames are generated until the log has ``rows`` rows (cut to exactly that).
    """
    rng = np.random.default_rng(seed)
    pos = rng.uniform(0.5, side - 0.5, size=(landmarks, 2))
    ids = np.array([f"tag_{k}" for k in range(landmarks)])
    chunks, n, frame, xy, heading = [], 0, 0, np.array([side / 2, side / 2]), 0.0
    half_fov = np.radians(fov_deg) / 2
    while n < rows:
        block = 5000  # frames simulated at once (the walk itself is sequential)
        turns = rng.normal(0.0, 0.15, size=block)
        poses = np.empty((block, 3))
        for k in range(block):
            step = 0.05 * np.array([np.cos(heading), np.sin(heading)])
            if not np.all((xy + 10 * step > 0.3) & (xy + 10 * step < side - 0.3)):
                heading += np.pi / 2 + rng.uniform(-0.5, 0.5)  # turn away from a wall
            else:
                xy = xy + step
            heading += turns[k]
            poses[k] = (*xy, heading)
        d = pos[None, :, :] - poses[:, None, :2]
        dist = np.hypot(d[..., 0], d[..., 1])
        bearing = np.angle(np.exp(1j * (np.arctan2(d[..., 1], d[..., 0]) - poses[:, 2:3])))
        seen = (dist < max_range) & (np.abs(bearing) < half_fov)
        f, j = np.nonzero(seen)
        b = np.angle(np.exp(1j * (bearing[f, j] + rng.normal(0, np.radians(bearing_sd_deg),
                                                             f.size))))
        chunks.append(pd.DataFrame({
            "time": (frame + f) / rate_hz, "landmark": ids[j], "bearing": b,
            "range": np.maximum(dist[f, j] + rng.normal(0, range_sd, f.size), 0.0)}))
        n += f.size
        frame += block
    log = pd.concat(chunks, ignore_index=True).iloc[:rows]
    truth = pd.DataFrame({"landmark": ids, "x": pos[:, 0], "y": pos[:, 1]})
    return log, truth


def _corner_anchors(truth: pd.DataFrame) -> pd.DataFrame:
    xy = truth[["x", "y"]].to_numpy()
    lo, hi = xy.min(axis=0), xy.max(axis=0)
    rows = []
    for c in ((lo[0], lo[1]), (hi[0], lo[1]), (hi[0], hi[1]), (lo[0], hi[1])):
        d = np.linalg.norm(xy - np.asarray(c), axis=1)
        d[rows] = np.inf
        rows.append(int(np.argmin(d)))
    return truth.iloc[rows]


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rows", type=int, default=1_000_000)
    ap.add_argument("--landmarks", type=int, default=200)
    ap.add_argument("--sensor", default="range")
    ap.add_argument("--bin", type=float, default=None, help="--bin of lfmdr map (seconds)")
    ap.add_argument("--method", default=None)
    ap.add_argument("--csv", action="store_true", help="write the log as CSV, not Parquet")
    ap.add_argument("--repeat", type=int, default=1)
    args = ap.parse_args(argv)

    with tempfile.TemporaryDirectory(prefix="bench-map-log-") as tmp:
        tmp = Path(tmp)
        log, truth = simulate_log(args.rows, args.landmarks)
        path = tmp / ("log.csv" if args.csv else "log.parquet")
        if args.csv:
            log.to_csv(path, index=False)
        else:
            log.to_parquet(path, index=False)
        _corner_anchors(truth).to_csv(tmp / "anchors.csv", index=False)
        truth.to_csv(tmp / "truth.csv", index=False)
        frames = log["time"].nunique()
        print(f"log: {len(log):,} rows, {log['landmark'].nunique()} landmarks, {frames:,} frames "
              f"({path.suffix[1:]}, {path.stat().st_size / 1e6:.1f} MB)")
        cmd = [sys.executable, "-m", "lfmdr_gym.cli", "map", str(path), "--anchors",
               str(tmp / "anchors.csv"), "--truth", str(tmp / "truth.csv"), "--sensor",
               args.sensor, "--out", str(tmp / "out")]
        if args.bin is not None:
            cmd += ["--bin", str(args.bin)]
        if args.method is not None:
            cmd += ["--method", args.method]
        print("command: lfmdr " + " ".join(cmd[3:]).replace(str(tmp) + "/", ""))
        times = []
        for _ in range(args.repeat):
            t0 = time.perf_counter()
            done = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True)
            times.append(time.perf_counter() - t0)
            if done.returncode:
                print(done.stdout + done.stderr)
                return 1
        print(done.stdout.strip())
        scores = json.loads((tmp / "out" / "scores.json").read_text())
        median = statistics.median(times)
        print(f"lfmdr map: {median:.1f} s wall (median of {len(times)}; goal < {GOAL_SECONDS:.0f} s"
              f": {'met' if median < GOAL_SECONDS else 'NOT met'}); MPE non-anchor "
              f"{scores['mpe_nonanchor']:.3f} m over {scores['n_scored_nonanchor']} landmarks")
    return 0


if __name__ == "__main__":
    sys.exit(main())
