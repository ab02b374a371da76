"""A camera among tags on posts and walls: one 3-D world, mapped from rays and ranges, from rays
alone and from sightings alone.

``LFMDR-Camera3D-v0`` keeps the robot on the floor of the paper's arena but hangs its 50 tags
at heights of 0-2 m, on posts and on the walls, and gives it a pitched camera with a 90 x 70
degree view and a 3 m range. The dimension of a map comes from its anchors: the env's six
anchors are (6, 3), so ``build_map`` makes a 3-D map with the 3-D default for each sensor
(SPATIAL-BA, a bundle adjustment of the tags and each step's 6-DoF pose, for rays; COVIS-3D,
co-observation, for sightings). The truth only scores.

    python examples/camera3d_map.py [--steps 2000] [--seed 0] [--out camera3d.png]
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

import lfmdr_gym  # noqa: F401  (registers the env ids)
import mappers
from lfmdr_gym import RandomWalkPolicy, collect

ENV_ID = "LFMDR-Camera3D-v0"
SENSORS = {  # the sensor and its noise: 1 degree on each ray, 2 cm on each range
    "range-bearing": {"bearing_noise_deg": 1.0, "range_noise": 0.02},
    "bearing": {"bearing_noise_deg": 1.0},
    "visibility": {},
}


def main(argv: list[str] | None = None) -> dict[str, float]:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=2000)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--out", default="camera3d.png", help="three views of the first map")
    args = parser.parse_args(argv)

    errors, first = {}, None
    for sensor, noise in SENSORS.items():
        # the same seed: the same tags and the same walk, read by another sensor
        history = collect(ENV_ID, RandomWalkPolicy(), args.steps, seed=args.seed,
                          make_kwargs={"sensor": sensor, **noise})
        result = mappers.build_map(history, history.anchor_ids, history.anchor_positions)
        skip = sorted({*history.anchor_ids.tolist(), *result.unmapped})
        mpe = mappers.mean_position_error_3d(result.positions, history.object_positions,
                                             exclude=skip)
        keep = np.setdiff1d(np.arange(history.n_objects), skip)
        diff = result.positions[keep] - history.object_positions[keep]
        print(f"{sensor:<14} {result.method:<11} MPE {mpe:.3f} m (floor "
              f"{np.linalg.norm(diff[:, :2], axis=1).mean():.3f} m, height "
              f"{np.abs(diff[:, 2]).mean():.3f} m), unmapped {list(result.unmapped)}")
        for w in result.warnings:  # what the mapper repaired or doubts (Map.warnings)
            print(f"warning: {w}")
        errors[sensor] = mpe
        first = first or (history, result, sensor, mpe)

    from lfmdr_gym.experiments.figures import plot_views_3d

    history, result, sensor, mpe = first
    path = plot_views_3d(result.positions, history.object_positions, history.anchor_ids,
                         Path(args.out), title=f"{ENV_ID}, {sensor}: {result.method}, MPE "
                                               f"{mpe:.3f} m", notes=result.warnings)
    print(f"wrote {path}")
    return errors


if __name__ == "__main__":
    main()
