"""The MRCLAM robots' camera in simulation: one walk of ``LFMDR-Camera-v0``, mapped from range and
bearing fused, and from each alone.

``LFMDR-Camera-v0`` observes the range and bearing of the objects in a 67.7-degree view, with the
noise measured from the real robots' logs (``lfmdr_gym.sim.camera.CAMERA_PRESET``; how:
docs/fused-sensing.md). ``collect`` records both into one fused History; ``build_map`` maps it
with the range-bearing default (LOC-SMA), and ``History.parts`` gives each sensor alone.

    python examples/mrclam_camera.py [--steps 2000] [--seed 3] [--out mrclam_camera.npz]
"""

from __future__ import annotations

import argparse

import lfmdr_gym
import mappers
from lfmdr_gym import History, collect
from lfmdr_gym.sim.camera import CAMERA_PRESET


def main(argv: list[str] | None = None) -> History:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=2000)
    parser.add_argument("--seed", type=int, default=3)
    parser.add_argument("--out", default="mrclam_camera.npz", help="the fused history file")
    args = parser.parse_args(argv)

    print(f"LFMDR-Camera-v0: {dict(CAMERA_PRESET)}")
    history = collect("LFMDR-Camera-v0", lfmdr_gym.RandomWalkPolicy(), args.steps, seed=args.seed)
    print(history)
    history.save(args.out)  # `lfmdr map FILE` maps it like any other history file

    for name, h in (("range + bearing", history), *history.parts.items()):
        result = mappers.build_map(h, h.anchor_ids, h.anchor_positions)
        skip = sorted({*h.anchor_ids.tolist(), *result.unmapped})
        mpe = mappers.mean_position_error(result.positions, h.object_positions, exclude=skip)
        print(f"{name:>16}: {result.method:<15} MPE {mpe:.3f} m (non-anchor), "
              f"unmapped {len(result.unmapped)}")
        for w in result.warnings:  # e.g. a fold the mapper suspects: read the map with care
            print(f"{'':>16}  warning: {w}")
    print(f"wrote {args.out}")
    return history


if __name__ == "__main__":
    main()
