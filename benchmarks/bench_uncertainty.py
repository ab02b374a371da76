"""Per-landmark uncertainty (``build_map(uncertainty=True)``): is it calibrated, sharp and cheap?

    python benchmarks/bench_uncertainty.py [--layouts 25] [--steps 1000] [--seed0 12000]
        [--sets visibility,bearing,range-bearing,bearing-view90,mrclam,starloc,...] [--setups s3]
        [--uncertainty true|anchors] [--csv docs/results/uncertainty/uncertainty.csv]

Simulated sets: each layout is one random walk of ``LFMDR-Bearing-v0`` (50 objects, 4 corner
anchors), seeds ``seed0, seed0 + 1, ...`` (fresh: never used to choose a setting), and from its
true poses and layout (:mod:`bench_fusion_sim`'s sensors):

* ``visibility``: the visibility bits of the walk's poses (the env's model, occlusion on),
  mapped by the default (``CAL-SMA``; uncertainty by its linearised block jackknife,
  ``--uncertainty bootstrap``: the bootstrap over steps);
* ``bearing``: 360-degree bearings with 2 degrees of Gaussian noise (``BEARING-BA``; model);
* ``range-bearing``: 360 degrees, 2 degrees and 2 cm of noise, fused (``LOC-SMA`` refined by its
  range-bearing adjustment; model);
* ``bearing-view90``: bearings through a 90-degree view (masked), 2 degrees of noise
  (``BEARING-BA``; model);
* ``visibility-other-sim``: visibility from a second, independent world
  (:func:`bench_view_other_sim.other_sim`: uniform layout without spacing rule, no occlusion,
  its own walk, a 0.55 m visibility radius, 360-degree view), 50 objects, ``--steps`` steps —
  the body of data the jackknife's and the bootstrap's inflations
  (:data:`mappers.covariances.JACKKNIFE_INFLATION`, :data:`mappers.covariances.BOOTSTRAP_INFLATION`)
  were chosen on; ``visibility`` confirms them.

The line ``inflation for 0.95`` printed per set is the factor on the covariances that would put
95 % of its landmarks inside their regions: with ``--no-inflation``, how
:data:`mappers.covariances.JACKKNIFE_INFLATION` (the visibility default's, ``--uncertainty
true``) and :data:`mappers.covariances.BOOTSTRAP_INFLATION` (``--uncertainty bootstrap``) were
chosen, on ``visibility-other-sim`` (seeds 13000-13014).

``mrclam``: every MRCLAM run under ``--data`` mapped from range and bearing fused (the logged-run
default, ``LOC-SMA``), scored against motion capture; ``mrclam-model`` and ``starloc-model``:
with ``uncertainty="model"`` (the model alone, without the floor ``True`` estimates from the
held-out anchors). ``mrclam-inflated`` asks what a calibrated
inflation would give: for each run, the factor on the covariances that puts 95 % of the *other*
runs' landmarks inside their regions (leave-one-run-out: the run's figure does not come from a
factor chosen on it), applied to that run (not a default of the library: the figures say
whether one factor carries from run to run).

``mrclam-anchors``: the same runs with ``uncertainty="anchors"`` (the covariances checked and
scaled by the held-out anchors, :mod:`mappers.core.held_out_anchors`). ``starloc`` and
``starloc-anchors``: every STAR-loc s3 sequence under ``--starloc`` mapped from stereo rays and
ranges (SPATIAL-BA, :func:`lfmdr_gym.experiments.starloc.map_starloc`), its scored tags scored
in 3-D (chi-squared(3)), with ``uncertainty=True`` and ``"anchors"``; ``--setups s1,s2`` maps
the sequences of those setups instead of s3's. ``mrclam-floor`` and ``starloc-floor``: with
``uncertainty="floor"`` (the model plus the systematic floor,
:func:`mappers.core.uncertainty.systematic_floor`). For ``mrclam-model`` and
``starloc-model`` the line ``floor for 0.95`` gives the smallest share of the anchors' extent
(:data:`FLOOR_GRID`) whose floor on the model's covariances puts 95 % of the set's landmarks inside their regions: how
:data:`mappers.core.uncertainty.SYSTEMATIC_FLOOR` was chosen (on the s3 sequences' model
covariances). ``--uncertainty anchors`` asks the simulated sets for ``"anchors"`` instead of
True.

Per map: the share of non-anchor landmarks whose truth lies inside their 95 % region (squared
Mahalanobis distance at most the chi-squared(2) 0.95 quantile), the mean RMS radius of their
95 % ellipses (:func:`mappers.core.uncertainty.rms_radius`), their mean position error, and the
CPU and wall time of the map alone and of the map with its uncertainty (both built in turn in
this process). The summary per set pools the landmarks of all maps: coverage (goal 0.88-0.99
simulated, >= 0.80 real), sharpness = mean RMS radius / mean error (goal <= 3; a calibrated
Gaussian gives about 1.95), and the ratio of the median CPU times with and without uncertainty
(goal <= 1.5). ``wide`` counts the landmarks whose 95 % region is wider than the anchors'
extent (its RMS radius above the largest distance between two anchors: "anywhere on the map",
e.g. a landmark no reading fixes in some direction), and ``sharp. rest`` is the sharpness of the
others (CSV: ``n_wide``, ``rms_radius_informative``, ``mpe_informative``): one such region
can make the mean RMS radius, and so the sharpness, meaningless.
"""

from __future__ import annotations

import argparse
import csv
import io
import math
import time
import warnings
from pathlib import Path

import gymnasium as gym
import numpy as np
from bench_fusion_sim import simulate_camera, visibility_history
from bench_view_other_sim import other_sim
from report import pool_uncertainty

import lfmdr_gym  # noqa: F401  (registers the env ids)
from lfmdr_gym import collect
from lfmdr_gym.atomic import atomic_write_text
from lfmdr_gym.exploration.random_walk import RandomWalkPolicy
from mappers import build_map, covariances
from mappers.core.uncertainty import chi2_quantile, mahalanobis_squared, rms_radius

SETS = ("visibility", "bearing", "range-bearing", "bearing-view90", "visibility-other-sim",
        "mrclam", "mrclam-model", "mrclam-anchors", "mrclam-floor", "starloc", "starloc-model",
        "starloc-anchors", "starloc-floor")
REAL = {"mrclam", "mrclam-model", "mrclam-anchors", "mrclam-floor", "starloc", "starloc-model",
        "starloc-anchors", "starloc-floor"}
FLOOR_GRID = np.round(np.arange(0.0005, 0.0201, 0.0005), 4)
"""The shares of the anchors' extent ``floor for 0.95`` is sought among (module docstring)."""


def real_mode(name: str) -> bool | str:
    """The ``uncertainty`` a real set asks for: its name's suffix ("-model", "-anchors",
    "-floor"), else True."""
    return name.rsplit("-", 1)[1] if name.endswith(("-model", "-anchors", "-floor")) else True


def floor_for(rows: list[dict], level: float = 0.95) -> float:
    """The smallest share of :data:`FLOOR_GRID` whose systematic floor
    (:func:`mappers.core.uncertainty.systematic_floor`) on the rows' covariances puts ``level``
    of their pooled landmarks inside their 95 % regions (NaN: none does)."""
    for share in FLOOR_GRID:
        inside = n = 0
        for r in rows:
            cov = r["_c"] + (share * r["_ext"]) ** 2 * np.eye(r["_c"].shape[-1])
            q = mahalanobis_squared(r["_e"], cov)
            inside += int(np.sum(q <= chi2_quantile(r["_e"].shape[1])))
            n += len(q)
        if inside >= level * n:
            return float(share)
    return math.nan
UNCERTAINTY: bool | str = True
"""What the simulated sets ask ``build_map`` for (``--uncertainty``)."""
FIELDS = ("set", "layout", "method", "n_scored", "inside", "rms_radius", "mpe", "cpu_map",
          "cpu_uncertainty", "wall_map", "wall_uncertainty", "n_wide", "rms_radius_informative",
          "mpe_informative")


def _timed(fn):
    t, cpu = time.perf_counter(), time.process_time()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        out = fn()
    return out, time.process_time() - cpu, time.perf_counter() - t


def score(positions, cov, truth, objects) -> tuple[int, int, float, float]:
    """(landmarks scored, inside their 95 % region, mean RMS radius, mean position error) over
    ``objects`` with a finite estimate."""
    objects = np.asarray(objects)
    objects = objects[np.all(np.isfinite(positions[objects]), axis=1)]
    q = mahalanobis_squared(truth[objects] - positions[objects], cov[objects])
    radius = rms_radius(cov[objects])
    err = np.linalg.norm(positions[objects] - truth[objects], axis=1)
    # an object without a covariance (NaN: e.g. seen in fewer than two of the jackknife's
    # blocks) counts as a miss and is left out of the mean radius
    return (len(objects), int(np.sum(q <= chi2_quantile(positions.shape[1]))),
            float(np.nanmean(radius)),
            float(np.mean(err)))


def informative(positions, cov, truth, objects, anchors_xyz) -> dict:
    """The landmarks whose 95 % region is wider than the anchors' extent (RMS radius above the
    largest distance between two anchors: the region says "anywhere on the map", e.g. a tag
    its readings fix only up to a turn) counted, and the mean RMS radius and position error of
    the others."""
    objects = np.asarray(objects)
    objects = objects[np.all(np.isfinite(positions[objects]), axis=1)]
    a = np.asarray(anchors_xyz, dtype=float)
    extent = float(np.max(np.linalg.norm(a[:, None] - a[None], axis=2)))
    radius = rms_radius(cov[objects])
    wide = radius > extent
    err = np.linalg.norm(positions[objects] - truth[objects], axis=1)
    keep = radius <= extent  # (neither: an object without a covariance, NaN)
    return {"n_wide": int(wide.sum()),
            "rms_radius_informative": float(np.mean(radius[keep])) if keep.any() else math.nan,
            "mpe_informative": float(np.mean(err[keep])) if keep.any() else math.nan}


def map_row(name, layout, histories, anchors, truth, **kwargs) -> dict:
    """One map without and with uncertainty, scored."""
    plain, cpu0, wall0 = _timed(lambda: build_map(histories, anchors, truth[anchors], **kwargs))
    m, cpu1, wall1 = _timed(lambda: build_map(histories, anchors, truth[anchors],
                                              uncertainty=UNCERTAINTY, **kwargs))
    if not np.array_equal(plain.positions, m.positions, equal_nan=True):
        raise AssertionError(f"{name} {layout}: uncertainty=True changed the map")
    objects = np.setdiff1d(np.arange(len(truth)), anchors)
    n, inside, radius, mpe = score(m.positions, m.covariances, truth, objects)
    ok = objects[np.all(np.isfinite(m.positions[objects]), axis=1)]
    q = mahalanobis_squared(truth[ok] - m.positions[ok], m.covariances[ok])
    return {"_q": q, "set": name, "layout": layout, "method": m.method, "n_scored": n, "inside": inside,
            "rms_radius": radius, "mpe": mpe, "cpu_map": cpu0, "cpu_uncertainty": cpu1,
            "wall_map": wall0, "wall_uncertainty": wall1,
            **informative(m.positions, m.covariances, truth, objects, truth[anchors])}


def simulated_rows(seed: int, steps: int, sets) -> list[dict]:
    rows = []
    if not set(sets) - REAL - {"visibility-other-sim"}:
        P, X, _ = other_sim(seed, n=steps, fov=360.0)
        return [map_row("visibility-other-sim", seed, X, np.arange(4), P, sensor="visibility")]
    env = gym.make("LFMDR-Bearing-v0")
    history = collect(env, RandomWalkPolicy.for_env(env, seed=seed), steps, seed=seed)
    radius = env.unwrapped.world.object_radius
    visual_angle = math.radians(env.unwrapped.visual_angle_deg)
    env.close()
    truth, anchors = history.object_positions, history.anchor_ids
    rng = np.random.default_rng(seed)
    if "visibility" in sets:
        vis = visibility_history(history, radius, visual_angle)
        rows.append(map_row("visibility", seed, vis, anchors, truth, sensor="visibility"))
    if "bearing" in sets:
        fused, _ = simulate_camera(history, 360.0, None, 2.0, 0.0, rng)
        rows.append(map_row("bearing", seed, fused["bearing"], anchors, truth, sensor="bearing"))
    if "range-bearing" in sets:
        fused, _ = simulate_camera(history, 360.0, None, 2.0, 0.02, rng)
        rows.append(map_row("range-bearing", seed, fused, anchors, truth))
    if "visibility-other-sim" in sets:
        P, X, _ = other_sim(seed, n=steps, fov=360.0)
        rows.append(map_row("visibility-other-sim", seed, X, np.arange(4), P,
                            sensor="visibility"))
    if "bearing-view90" in sets:
        fused, masks = simulate_camera(history, 90.0, None, 2.0, 0.0, rng)
        rows.append(map_row("bearing-view90", seed, fused["bearing"], anchors, truth,
                            sensor="bearing", mask=masks["bearing"]))
    return rows


def starloc_rows(data: Path, name: str, setups=("s3",)) -> list[dict]:
    """Every sequence of the ``setups`` under ``data`` mapped from stereo (rays and ranges,
    SPATIAL-BA with :data:`lfmdr_gym.experiments.starloc.STARLOC_PARAMS`), its scored tags
    scored in 3-D; ``name`` "starloc": ``uncertainty=True``, "starloc-anchors":
    ``uncertainty="anchors"``, "starloc-floor": ``"floor"``. A sequence that cannot be mapped
    is skipped with a line saying so."""
    from lfmdr_gym.datasets.starloc import read_starloc, scored_tags, starloc_survey
    from lfmdr_gym.experiments.starloc import map_starloc

    mode = real_mode(name)
    rows = []
    for seq in sorted(p for p in (data / "data").iterdir()
                      if p.is_dir() and p.name.rsplit("_", 1)[-1] in setups):
        try:
            plain, cpu0, wall0 = _timed(lambda s=seq: map_starloc(s))
        except ValueError as e:  # (a MappingError: loop-2d-fast_s2 places no step)
            print(f"{seq.name}: not mapped ({e})", flush=True)
            continue
        r, cpu1, wall1 = _timed(lambda s=seq: map_starloc(s, uncertainty=mode))
        xyz = starloc_survey(seq).set_index("landmark")[["x", "y", "z"]]
        tags = scored_tags(read_starloc(seq, "range-bearing"), starloc_survey(seq), r.anchors)
        tags = [t for t in tags if t in r.positions]
        if not tags:
            continue
        pos = np.array([r.positions[t] for t in tags])
        cov = np.array([r.covariances[t] for t in tags])
        truth = xyz.loc[tags].to_numpy(dtype=float)
        n, inside, radius, mpe = score(pos, cov, truth, np.arange(len(tags)))
        # the anchors' known positions (an anchor SPATIAL-BA did not place has none in the map)
        extent = xyz.loc[list(r.anchors)].to_numpy(dtype=float)
        rows.append({"_q": mahalanobis_squared(truth - pos, cov), "_e": truth - pos, "_c": cov,
                     "_ext": float(np.max(np.linalg.norm(extent[:, None] - extent[None],
                                                         axis=2))), "set": name,
                     "layout": seq.name, "method": r.method, "n_scored": n, "inside": inside,
                     "rms_radius": radius, "mpe": mpe, "cpu_map": cpu0, "cpu_uncertainty": cpu1,
                     "wall_map": wall0, "wall_uncertainty": wall1,
                     **informative(pos, cov, truth, np.arange(len(tags)), extent)})
    return rows


def mrclam_rows(data: Path, name: str = "mrclam") -> list[dict]:
    from lfmdr_gym.experiments.mrclam import map_mrclam_run

    mode = real_mode(name)
    rows, q_runs = [], {}
    for run_dir in sorted(p for p in data.glob("MRCLAM_Dataset*") if p.is_dir()):
        plain, cpu0, wall0 = _timed(lambda d=run_dir: map_mrclam_run(d, "range-bearing",
                                                                      plot=False))
        r, cpu1, wall1 = _timed(lambda d=run_dir: map_mrclam_run(d, "range-bearing", plot=False,
                                                                 uncertainty=mode))
        anchors = np.flatnonzero(np.isin(r.subjects, r.anchor_subjects))
        objects = np.setdiff1d(np.arange(len(r.subjects)), anchors)
        n, inside, radius, mpe = score(r.positions, r.covariances, r.truth, objects)
        ok = objects[np.all(np.isfinite(r.positions[objects]), axis=1)]
        a = r.positions[anchors]
        rows.append({"_q": mahalanobis_squared(r.truth[objects] - r.positions[objects],
                                               r.covariances[objects]),
                     "_e": r.truth[ok] - r.positions[ok], "_c": r.covariances[ok],
                     "_ext": float(np.max(np.linalg.norm(a[:, None] - a[None], axis=2))),
                     "set": name, "layout": run_dir.name, "method": r.method, "n_scored": n,
                     "inside": inside, "rms_radius": radius, "mpe": mpe, "cpu_map": cpu0,
                     "cpu_uncertainty": cpu1, "wall_map": wall0, "wall_uncertainty": wall1,
                     **informative(r.positions, r.covariances, r.truth, objects,
                                   r.truth[anchors])})
        ok = objects[np.all(np.isfinite(r.positions[objects]), axis=1)]
        q_runs[run_dir.name] = mahalanobis_squared(r.truth[ok] - r.positions[ok],
                                                   r.covariances[ok])
    for row in list(rows) if mode == "model" else []:  # leave-one-run-out (module docstring)
        others = np.concatenate([q for name, q in q_runs.items() if name != row["layout"]])
        if not others.size:
            continue
        factor = float(np.quantile(others, 0.95)) / chi2_quantile(2)
        rows.append({**row, "set": "mrclam-inflated", "_q": q_runs[row["layout"]] / factor,
                     "inside": int(np.sum(q_runs[row["layout"]] <= factor * chi2_quantile(2))),
                     "rms_radius": row["rms_radius"] * math.sqrt(factor),
                     "rms_radius_informative": (row["rms_radius_informative"]
                                                * math.sqrt(factor))})
    return rows


def summary(rows: list[dict]) -> list[dict]:
    """Per set: layouts, coverage, sharpness and the CPU-time ratio (module docstring), pooled
    as the benchmarks page pools them (``report.pool_uncertainty``)."""
    return [{"set": name, "layouts": len(rs), "method": rs[0]["method"], **figures}
            for name, rs, figures in pool_uncertainty(rows)]


def write_csv(path: Path, rows: list[dict]) -> None:
    buf = io.StringIO()
    writer = csv.DictWriter(buf, fieldnames=FIELDS, lineterminator="\n")
    writer.writeheader()
    for r in rows:
        writer.writerow({k: (f"{v:.6g}" if isinstance(v, float) else v) for k, v in r.items()
                         if not k.startswith("_")})
    atomic_write_text(path, buf.getvalue())


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--layouts", type=int, default=25)
    ap.add_argument("--steps", type=int, default=1000)
    ap.add_argument("--seed0", type=int, default=12000)
    ap.add_argument("--sets", default=",".join(SETS))
    ap.add_argument("--data", type=Path, default=Path("/work/shared/data/mrclam"))
    ap.add_argument("--starloc", type=Path, default=Path("/work/shared/data/starloc"))
    ap.add_argument("--setups", default="s3",
                    help="the STAR-loc setups the starloc sets map (comma-separated: s1,s2,s3)")
    ap.add_argument("--csv", type=Path, default=None)
    ap.add_argument("--uncertainty", choices=("true", "model", "anchors", "jackknife",
                                              "bootstrap"),
                    default="true",
                    help="the simulated sets' mode: True, 'anchors' (held-out anchors' check), "
                         "or 'jackknife' / 'bootstrap' (visibility: the linearised jackknife, the "
                         "default, or the bootstrap over steps)")
    ap.add_argument("--no-inflation", action="store_true",
                    help="the jackknife's and the bootstrap's covariances without their "
                         "inflation (JACKKNIFE_INFLATION, BOOTSTRAP_INFLATION at 1): how the "
                         "factors are chosen")
    args = ap.parse_args(argv)
    if args.no_inflation:
        covariances.JACKKNIFE_INFLATION = covariances.BOOTSTRAP_INFLATION = 1.0
    global UNCERTAINTY
    UNCERTAINTY = True if args.uncertainty == "true" else args.uncertainty
    sets = [s for s in args.sets.split(",") if s]
    unknown = set(sets) - set(SETS)
    if unknown:
        ap.error(f"unknown sets {sorted(unknown)}; choose from {list(SETS)}")
    rows: list[dict] = []
    for name in [s for s in sets if s in REAL]:
        data = args.starloc if name.startswith("starloc") else args.data
        if not data.is_dir():
            ap.error(f"no {name.split('-')[0]} data at {data}")
        rows += (starloc_rows(data, name, tuple(args.setups.split(",")))
                 if name.startswith("starloc") else mrclam_rows(data, name))
        if args.csv:
            write_csv(args.csv, rows)
    for k in range(args.layouts if set(sets) - REAL else 0):
        rows += simulated_rows(args.seed0 + k, args.steps, sets)
        if args.csv:
            write_csv(args.csv, rows)  # after every layout: a partial run keeps its rows
        print(f"layout {k + 1}/{args.layouts} done", flush=True)
    print(f"{'set':<16}{'layouts':>8}{'coverage':>10}{'sharpness':>11}{'MPE [m]':>10}"
          f"{'time x':>8}{'wide':>6}{'sharp. rest':>12}  method")
    for s in summary(rows):
        print(f"{s['set']:<16}{s['layouts']:>8}{s['coverage']:>10.3f}{s['sharpness']:>11.2f}"
              f"{s['mpe']:>10.4f}{s['time_ratio']:>8.2f}{s['wide']:>6}"
              f"{s['sharpness_informative']:>12.2f}  {s['method']}")
    for name in dict.fromkeys(r["set"] for r in rows):
        q = np.concatenate([r["_q"] for r in rows if r["set"] == name])
        d = 3 if name.startswith("starloc") else 2
        print(f"{name}: inflation for 0.95 = {np.nanquantile(q, 0.95) / chi2_quantile(d):.3f}")
        if name in ("mrclam-model", "starloc-model"):
            print(f"{name}: floor for 0.95 = "
                  f"{floor_for([r for r in rows if r['set'] == name]):.4f} of the anchors' extent")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
