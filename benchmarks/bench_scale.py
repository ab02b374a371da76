"""Time and peak memory of collecting and of mapping against the number of objects M.

The world at the paper's density (arena side 2.5 sqrt(M / 50) m), 8 % of the objects as random
anchors (at least 4), the random-walk agent, the visibility sensor (or ``--sensor bearing``).
Steps N per M follow the issue's figures: 2,000 at M = 50 (the paper), then 8,000, 20,000
and, with ``--full``, 400,000 at M = 10,000 (the paper's path length per square metre);
``--sizes 300`` (6,000 steps) is a second body for the large masked bearing route. Each
case runs in its own subprocess, so its peak resident memory (``resource.getrusage``,
ru_maxrss) is its own; the import baseline (the RSS before the work) is printed beside it. A
method that refuses a size prints its reason; one that runs past ``--timeout`` is reported as such.

    python benchmarks/bench_scale.py                  # M = 50, 200, 1000
    python benchmarks/bench_scale.py --full           # and M = 10,000 (~5 CPU-min)
    python benchmarks/bench_scale.py --sensor bearing --max-range 1.5  # masked
    python benchmarks/bench_scale.py --full --plot docs/scale.png --json scale.json

``--plot`` draws CPU time and peak memory against M for collect and each method (log-log; a
method that cannot run at a size has no point there), ``--json`` keeps every row. A method is a
label with optional parameters, ``"CAL-SMA:sparse=True"`` (CAL-SMA's scalable form).

With ``--max-range`` (a sensing limit of issue #11) the histories are masked and recorded
sparse at M = 1,000 (the observed entries and the mask), and the methods are those of
:data:`MASKED_METHODS`.
"""

from __future__ import annotations

import argparse
import json
import math
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

STEPS = {50: 2000, 200: 8000, 300: 6000, 1000: 20000, 10000: 400000}
METHODS = ("CAL-SMA:sparse=True", "CAL-SMA", "SMA(WGT)", "ISOMAP", "LEM")
MASKED_METHODS = ("default", "COVIS-SPARSE", "COVIS-AUTO")
"""With ``--max-range`` the histories are masked: build_map's default (BEARING-BA, which starts
from COVIS-AUTO up to 500 objects and from COVIS-SPARSE above, there on the sparse Schur engine),
the sparse co-observation map alone and the dense one."""
ENV_IDS = {"visibility": "LFMDR-Visibility-v0", "bearing": "LFMDR-Bearing-v0"}


def _rss_mb() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0  # kB on Linux


def run_collect(m: int, path: str, sensor: str, max_range: float | None, seed: int) -> dict:
    """Collect one history at M = m and save it to ``path`` (compact above 64 MiB)."""
    from lfmdr_gym.exploration.random_walk import RandomWalkPolicy
    from lfmdr_gym.histories.recording import collect

    n = STEPS[m]
    kwargs = {"n_objects": m, "arena_size": 2.5 * math.sqrt(m / 50), "anchors": "random",
              "n_anchors": max(4, round(0.08 * m)), "max_episode_steps": n}
    if max_range is not None:
        kwargs["max_range"] = max_range
    base = _rss_mb()
    t0 = time.perf_counter()
    cpu0 = time.process_time()
    h = collect(ENV_IDS[sensor], RandomWalkPolicy(seed=0), n, seed=seed, make_kwargs=kwargs)
    out = {"seconds": time.perf_counter() - t0, "cpu_seconds": time.process_time() - cpu0}
    h.save(path)
    return {**out, "steps": n, "compact": h.compact, "peak_mb": _rss_mb(), "base_mb": base}


def run_method(path: str, method: str) -> dict:
    """Map the saved history with ``method``; time, peak memory, MPE and MOE (non-anchors)."""
    import mappers
    from lfmdr_gym.experiments.params import parse_params
    from lfmdr_gym.histories.history import History
    from mappers.core.scores import (
        mean_orientation_error,
        mean_position_error,
        sampled_orientation_error,
    )

    h = History.load(path)
    label, _, given = method.partition(":")
    params = parse_params(given.split(",") if given else None)
    label = None if label == "default" else label  # "default": build_map's own choice
    _ = mappers.METHODS["CAL-SMA" if label is None else label]  # load the registry before timing
    build_map = mappers.build_map  # and the pipeline (imported on first access, ~2-3 s of imports)
    base = _rss_mb()
    t0 = time.perf_counter()
    cpu0 = time.process_time()
    try:
        m = build_map(h, h.anchor_ids, h.anchor_positions, method=label, **params)
    except ValueError as exc:
        return {"refused": str(exc)}
    out = {"method": m.method, "seconds": time.perf_counter() - t0, "cpu_seconds": time.process_time() - cpu0,
           "peak_mb": _rss_mb(), "base_mb": base}
    ex = sorted({*h.anchor_ids.tolist(), *m.unmapped})
    out["mpe"] = mean_position_error(m.positions, h.object_positions, exclude=ex)
    t0 = time.perf_counter()
    if h.n_objects <= 2000:
        out["moe"], out["moe_how"] = mean_orientation_error(m.positions, h.object_positions, exclude=ex), "exact"
    else:
        moe, (lo, hi) = sampled_orientation_error(m.positions, h.object_positions, exclude=ex)
        out["moe"], out["moe_how"] = moe, f"sampled, 95% CI [{lo:.3f}, {hi:.3f}]"
    out["moe_seconds"] = time.perf_counter() - t0
    return out


def _metres(x: float) -> str:
    """An error [m] to 4 decimals, or in powers of ten below a millimetre (a map that is exact
    up to the solver's tolerance)."""
    return f"{x:.4f}" if x >= 1e-3 else f"{x:.1e}"


def _child(args: list[str], timeout: float) -> dict:
    cmd = [sys.executable, __file__, "--child", *args]
    try:
        done = subprocess.run(cmd, capture_output=True, text=True, timeout=timeout, check=False)
    except subprocess.TimeoutExpired:
        return {"refused": f"did not finish within {timeout:.0f} s"}
    if done.returncode != 0:
        tail = (done.stderr.strip().splitlines() or ["?"])[-1]
        return {"refused": f"failed (exit {done.returncode}): {tail}"}
    return json.loads(done.stdout.strip().splitlines()[-1])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--full", action="store_true", help="also M = 10,000 (N = 400,000)")
    parser.add_argument("--sizes", type=int, nargs="*", default=None, help="values of M")
    parser.add_argument("--methods", nargs="*", default=None,
                        help="method labels, with parameters as LABEL:NAME=VALUE,...; 'default' = "
                             "build_map's choice (method=None)")
    parser.add_argument("--sensor", choices=sorted(ENV_IDS), default="visibility")
    parser.add_argument("--max-range", type=float, default=None)
    parser.add_argument("--seed", type=int, default=101, help="episode seed (not tuned on)")
    parser.add_argument("--timeout", type=float, default=900.0, help="seconds per method case")
    parser.add_argument("--plot", default=None, help="write the figure (PNG) here")
    parser.add_argument("--json", default=None, help="write every row (JSON) here")
    parser.add_argument("--child", nargs="+", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.child:
        kind, *rest = args.child
        if kind == "collect":
            mr = None if rest[3] == "none" else float(rest[3])
            out = run_collect(int(rest[0]), rest[1], rest[2], mr, int(rest[4]))
        else:
            out = run_method(rest[0], rest[1])
        print(json.dumps(out))
        return
    sizes = args.sizes or ([50, 200, 1000, 10000] if args.full else [50, 200, 1000])
    if args.methods is None:
        args.methods = list(MASKED_METHODS if args.max_range is not None else METHODS)
    print(f"{args.sensor} histories, 8 % random anchors, seed {args.seed}; wall s (CPU s), peak RSS MB "
          f"(import baseline)")
    rows: list[dict] = []
    with tempfile.TemporaryDirectory() as tmp:
        for m in sizes:
            path = str(Path(tmp) / f"h{m}.npz")
            c = _child(["collect", str(m), path, args.sensor, str(args.max_range).lower(),
                        str(args.seed)], 4 * 3600)
            rows.append({"M": m, "what": "collect", **c})
            if "refused" in c:
                print(f"M={m:>6} collect: {c['refused']}")
                continue
            print(f"M={m:>6} N={c['steps']:>7} collect {c['seconds']:8.1f} s ({c['cpu_seconds']:.1f}) "
                  f"peak {c['peak_mb']:7.0f} MB ({c['base_mb']:.0f}) compact={c['compact']}")
            for method in args.methods:
                r = _child(["map", path, method], args.timeout)
                rows.append({"M": m, "what": method, **r})
                if "refused" in r:
                    print(f"         {method:<18} cannot run: {r['refused'][:150]}")
                    continue
                name = method if method != "default" else f"default ({r['method']})"
                print(f"         {name:<18} {r['seconds']:8.1f} s ({r['cpu_seconds']:.1f}) peak "
                      f"{r['peak_mb']:7.0f} MB ({r['base_mb']:.0f})  MPE {_metres(r['mpe'])} m  "
                      f"MOE {r['moe']:.3f} % ({r['moe_how']}, {r['moe_seconds']:.1f} s)")
            sys.stdout.flush()
    if args.json:
        from lfmdr_gym.atomic import atomic_write_text

        atomic_write_text(args.json, json.dumps(rows, indent=1) + "\n")
    if args.plot:
        plot(rows, args.plot, f"{args.sensor}, seed {args.seed}")


def plot(rows: list[dict], path: str, title: str) -> None:
    """CPU time and peak memory against M, one line per case (collect and each method)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from lfmdr_gym.atomic import atomic_savefig

    fig, (ax_t, ax_m) = plt.subplots(1, 2, figsize=(9.0, 3.6), constrained_layout=True)
    for what in dict.fromkeys(r["what"] for r in rows):
        done = [r for r in rows if r["what"] == what and "refused" not in r]
        if not done:
            continue
        label = what if what != "default" else f"default ({done[-1]['method']})"
        style = {"marker": "o", "ls": "--" if what == "collect" else "-"}
        ms = [r["M"] for r in done]
        ax_t.plot(ms, [r["cpu_seconds"] for r in done], label=label, **style)
        ax_m.plot(ms, [r["peak_mb"] for r in done], label=label, **style)
    for ax, ylabel in ((ax_t, "CPU time [s]"), (ax_m, "peak resident memory [MB]")):
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xlabel("objects M (N steps grows with M)")
        ax.set_ylabel(ylabel)
        ax.grid(True, which="both", alpha=0.3)
    ax_t.legend(fontsize=7)
    fig.suptitle(f"lfmdr at scale: {title} (no point: refused or timed out)", fontsize=9)
    atomic_savefig(fig, path)
    plt.close(fig)


if __name__ == "__main__":
    main()
