"""Wall time of the paper's full protocol (both tables), as ``lfmdr reproduce`` runs it.

    python benchmarks/bench_protocol.py            # full: 2 x 25 runs, N=2000, --jobs 2
    python benchmarks/bench_protocol.py --quick    # 1 x 2 runs, N=400: a smoke test

Each mode runs into a fresh temporary directory (nothing resumed), episodes collected included.
Prints the wall time per mode and in total, the CPU time of the main process and its workers
(on a machine shared with other work, CPU / jobs estimates the wall time the run would take on
idle cores), the number of maps, and the slowest methods by summed mapper wall seconds (from
results.csv), so the figure can be traced to where the time goes.
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
from collections import defaultdict
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from lfmdr_gym.experiments.protocol import ProtocolConfig, run_protocol  # noqa: E402
from lfmdr_gym.experiments.store import read_results  # noqa: E402


def _cpu_seconds() -> float:
    """CPU seconds of this process and of its reaped children (the worker processes)."""
    t = os.times()
    return t.user + t.system + t.children_user + t.children_system


def _stop_workers() -> None:
    from joblib.externals.loky import get_reusable_executor

    get_reusable_executor().shutdown(wait=True)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--quick", action="store_true", help="1 layout x 2 poses, N=400, every 100")
    parser.add_argument("--jobs", type=int, default=2, help="worker processes")
    parser.add_argument("--sensors", "--modes", dest="modes", nargs="+", default=["visibility", "bearing"])
    parser.add_argument("--methods", nargs="+", default=None, help="restrict the methods")
    parser.add_argument("--keep", metavar="DIR", default=None,
                        help="write the run directories under DIR instead of a temporary one")
    args = parser.parse_args(argv)

    size = (dict(layouts=1, poses=2, steps=400, every=100) if args.quick
            else dict(layouts=5, poses=5, steps=2000))
    base = Path(args.keep) if args.keep else Path(tempfile.mkdtemp(prefix="lfmdr-bench-"))
    print(f"cores: {os.cpu_count()}, jobs: {args.jobs}, runs: {size['layouts'] * size['poses']} "
          f"per mode, N = {size['steps']}, out: {base}")
    total = total_cpu = 0.0
    for mode in args.modes:
        config = ProtocolConfig(sensor=mode, methods=args.methods, **size)
        out = base / mode
        t0, cpu0 = time.perf_counter(), _cpu_seconds()
        summary = run_protocol(config, out, jobs=args.jobs, progress=sys.stderr.isatty())
        wall = time.perf_counter() - t0
        _stop_workers()  # so that their CPU time is counted (children are counted once reaped)
        cpu = _cpu_seconds() - cpu0
        total += wall
        total_cpu += cpu
        rows = read_results(out / "results.csv")
        by_method: dict[str, float] = defaultdict(float)
        for r in rows:
            by_method[r["method"]] += r["seconds"]
        busy = sum(by_method.values())
        top = sorted(by_method.items(), key=lambda kv: -kv[1])[:4]
        print(f"{mode}: {wall:.1f} s wall, {cpu:.1f} s CPU for {summary.total_units} maps "
              f"({summary.failed} failed); mapper seconds summed {busy:.1f} s; slowest: "
              + ", ".join(f"{m} {s:.1f} s" for m, s in top))
    print(f"total wall time: {total:.1f} s ({total / 60:.2f} min); CPU {total_cpu:.1f} s, "
          f"i.e. {total_cpu / max(args.jobs, 1):.1f} s on {args.jobs} idle cores")
    uptime = os.getloadavg()
    print(f"load average now: {uptime[0]:.1f} (other work on the machine inflates wall time)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
