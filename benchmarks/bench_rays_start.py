"""Rays alone in 3-D: SPATIAL-BA's two starts side by side (issue 34), on STAR-loc's left camera
and on ``LFMDR-Camera3D-v0``.

    python benchmarks/bench_rays_start.py [--sequences eight_s3,grid_s3,...] [--seeds 34000,34001]
        [--starts anchors,global,incremental]

``start="anchors"`` (the default) resects and intersects from the anchors; ``start="global"``
is global structure from motion placed on the anchors at the end
(:mod:`mappers.spatial.global_start`); ``start="incremental"`` incremental structure from
motion with merging (:mod:`mappers.spatial.incremental`). Per sequence / layout and start: the
non-anchor MPE, the share of scored tags mapped and the CPU seconds of the map. STAR-loc with the benchmark's
anchors, scoring and bearing parameters (:func:`lfmdr_gym.experiments.starloc.map_starloc`);
``LFMDR-Camera3D-v0`` as ``benchmarks/bench_camera3d.py --sensors bearing`` (N = 2000, 1
degree). The data: ``<repo>/../shared/data/starloc`` (never copied into the repository).
"""

from __future__ import annotations

import argparse
import time
import warnings
from pathlib import Path

import numpy as np

import lfmdr_gym  # noqa: F401  (registers the env ids)
from lfmdr_gym import RandomWalkPolicy, collect
from lfmdr_gym.experiments.starloc import STARLOC_PARAMS, map_starloc
from mappers import build_map

ROOT = Path(__file__).resolve().parents[1]
DATA = ROOT.parent / "shared" / "data" / "starloc" / "data"


def camera3d(seed: int, start: str) -> tuple[float, float, float]:
    """(MPE, mapped share, CPU s) of one Camera3D layout's rays-only map with ``start``."""
    h = collect("LFMDR-Camera3D-v0", RandomWalkPolicy(), 2000, seed=seed,
                make_kwargs={"sensor": "bearing", "bearing_noise_deg": 1.0})
    cpu = time.process_time()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        m = build_map(h, h.anchor_ids, h.anchor_positions, start=start)
    cpu = time.process_time() - cpu
    rest = np.setdiff1d(np.arange(h.n_objects), h.anchor_ids)
    placed = rest[np.all(np.isfinite(m.positions[rest]), axis=1)]
    err = np.linalg.norm(m.positions[placed] - h.object_positions[placed], axis=1)
    return float(err.mean()), placed.size / rest.size, cpu


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sequences", default="eight_s3,grid_s3,loop-2d-fast_s3,loop-2d_s3,"
                                            "loop-3d_s3,zigzag_s3")
    ap.add_argument("--seeds", default="34000,34001,34002,34003,34004,34005")
    ap.add_argument("--starts", default="anchors,global,incremental")
    ap.add_argument("--data", type=Path, default=DATA)
    args = ap.parse_args(argv)
    starts = args.starts.split(",")
    print(f"{'data':18s} {'start':11s} {'MPE [m]':>8s} {'mapped':>7s} {'CPU [s]':>7s}")
    for seq in [s for s in args.sequences.split(",") if s]:
        for start in starts:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                r = map_starloc(args.data / seq, "bearing",
                                {**STARLOC_PARAMS["bearing"], "start": start})
            print(f"{seq:18s} {start:11s} {r.mpe:8.4f} {r.mapped:7.0%} {r.cpu_seconds:7.2f}",
                  flush=True)
    for seed in [int(s) for s in args.seeds.split(",") if s]:
        for start in starts:
            mpe, mapped, cpu = camera3d(seed, start)
            print(f"{'camera3d ' + str(seed):18s} {start:11s} {mpe:8.4f} {mapped:7.0%} {cpu:7.2f}",
                  flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
