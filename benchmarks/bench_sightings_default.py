"""The default for logs of sightings against DROPOUT-BLEND, the default before (issue 35).

A log of sightings (a table of detections: the mask says what was seen, not what was in view;
``mappers.defaults.is_sightings_log``) walked like a walk is mapped with ``COVIS-ENSEMBLE``
(windows of 1-6 steps, the geometric median of its members, ``DROPOUT-BLEND``'s map when the
members scatter: ``mappers.defaults``). This prints, per body of data, the mean non-anchor MPE
[m] (largest run in brackets; objects left unmapped counted, the MPE over the placed ones) of:

- ``default``: ``build_map`` with no method (the new default);
- ``DROPOUT-BLEND``: the default before;
- ``COVIS-ENSEMBLE (mean)``: the ensemble as ``lfmdr mrclam`` combines it (its own defaults),
  which fails on the simulators (one member flinging an object off moves the mean).

Bodies of data (``--data``): the project's world through a 90-degree view (``bench_masked_goals``'s
random walk, N = 2,000) and the second simulator (``bench_view_other_sim.py``), each with the mask
set to the sightings, 25 fresh layouts (world seeds from 1000, other from 0) or the tuning
layouts the default's windows were chosen on (``--tuning``: seeds 100-111 of both); MRCLAM's
four runs as ``lfmdr convert mrclam`` writes them (one step per camera frame, as ``lfmdr map``
reads the table).

    python benchmarks/bench_sightings_default.py                 # ~10 min on one core
    python benchmarks/bench_sightings_default.py --data mrclam   # ~1 min
"""

from __future__ import annotations

import argparse
import sys
import time
import warnings
from pathlib import Path

import numpy as np
from threadpoolctl import threadpool_limits

sys.path.insert(0, str(Path(__file__).resolve().parent))

from bench_defaults_carry import _other, _world, write_mrclam_tables  # noqa: E402

import mappers  # noqa: E402

METHODS = {"default": (None, {}), "DROPOUT-BLEND": ("DROPOUT-BLEND", {}),
           "COVIS-ENSEMBLE (mean)": ("COVIS-ENSEMBLE", {})}


def _sim_cases(make, seeds):
    for seed in seeds:
        X, mask, ids, apos, P = make(seed)
        yield f"seed {seed}", X, mask & (X > 0.5), ids, apos, P, None


def _mrclam_cases(data: Path):
    import tempfile

    from lfmdr_gym.histories.observation_table import read_landmarks, read_observations
    from lfmdr_gym.histories.observations import observations_to_history

    runs = sorted(p for p in data.glob("MRCLAM_Dataset*") if p.is_dir())
    if not runs:
        raise SystemExit(f"no MRCLAM_Dataset* directories under {data}")
    with tempfile.TemporaryDirectory() as tmp:
        for name, (log, anchors, truth) in write_mrclam_tables(runs, Path(tmp)).items():
            h = observations_to_history(
                read_observations(log), read_landmarks(anchors, what="anchors"),
                truth=read_landmarks(truth, what="truth"), sensor="visibility")
            dense = [m.toarray() if hasattr(m, "toarray") else np.asarray(m) for m in (h.matrix, h.mask)]
            # the truth is for the score only: the map sees the history and the anchors
            yield (name, dense[0].astype(float), dense[1].astype(bool), np.asarray(h.anchor_ids),
                   np.asarray(h.anchor_positions), np.asarray(h.object_positions), h.timeline)


def measure(name: str, cases) -> None:
    errs: dict[str, list[float]] = {k: [] for k in METHODS}
    lost, labels, cpu = dict.fromkeys(METHODS, 0), {k: set() for k in METHODS}, {k: [] for k in METHODS}
    for case, X, seen, ids, apos, P, timeline in cases:
        keep = np.setdiff1d(np.arange(len(P)), ids)
        line = []
        for key, (method, params) in METHODS.items():
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                t0 = time.process_time()
                m = mappers.build_map(X, ids, apos, method, sensor="visibility", mask=seen,
                                      timeline=timeline, **params)
                cpu[key].append(time.process_time() - t0)
            placed = keep[np.all(np.isfinite(m.positions[keep]), axis=1)]
            errs[key].append(mappers.mean_position_error(m.positions[placed], P[placed]))
            lost[key] += len(keep) - len(placed)
            fell_back = any("so the map is DROPOUT-BLEND's" in w for w in m.warnings)
            labels[key].add(m.method + (" -> DROPOUT-BLEND" if fell_back else ""))
            line.append(f"{key} {errs[key][-1]:.4f}")
        print(f"  {name} {case}: " + "  ".join(line), flush=True)
    for key, v in errs.items():
        a = np.array(v)
        print(f"{name:16s} {key:22s} {a.mean():.4f} ({a.max():.4f})  [{'; '.join(sorted(labels[key]))}; "
              f"{lost[key]} objects unmapped; CPU {np.median(cpu[key]):.2f} s per map (median)]")
    d, b = np.array(errs["default"]), np.array(errs["DROPOUT-BLEND"])
    print(f"{name:16s} default better than DROPOUT-BLEND on {int(np.sum(d < b))} of {len(d)}", flush=True)


def main(argv=None) -> None:
    here = Path(__file__).resolve().parents[1]
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--data", nargs="+", default=["world", "other", "mrclam"],
                    choices=["world", "other", "mrclam"])
    ap.add_argument("--runs", type=int, default=25, help="fresh layouts per simulator (default 25)")
    ap.add_argument("--tuning", action="store_true",
                    help="the simulators' tuning layouts (seeds 100-111) instead of fresh ones")
    ap.add_argument("--mrclam", type=Path, default=here.parent / "shared" / "data" / "mrclam")
    args = ap.parse_args(argv)
    print("## Logs of sightings: non-anchor MPE [m] mean (largest run)")
    with threadpool_limits(limits=1):
        for name in args.data:
            if name == "mrclam":
                measure("MRCLAM", _mrclam_cases(args.mrclam))
                continue
            make, first = {"world": (_world, 1000), "other": (_other, 0)}[name]
            seeds = range(100, 112) if args.tuning else range(first, first + args.runs)
            measure({"world": "project's world", "other": "other simulator"}[name], _sim_cases(make, seeds))


if __name__ == "__main__":
    main()
