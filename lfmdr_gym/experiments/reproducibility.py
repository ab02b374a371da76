"""What a result was computed with, and whether a fresh run reproduces a reference one.

On one machine the protocol is deterministic: the same command gives byte-identical tables. On
another machine (another CPU, BLAS build or package version) eigen- and SDP solvers round
differently, and the methods that hinge on them (LLE, HLLE, LEM, SDE) move in the third decimal.
So every run records its environment (``environment.json``), and :func:`compare_tables` checks a
fresh table against a reference within stated tolerances.
"""

from __future__ import annotations

import csv
import json
import math
import os
import platform
import sys
from importlib import metadata
from pathlib import Path
from typing import Any

from lfmdr_gym.atomic import atomic_write_text

__all__ = ["ENVIRONMENT", "TOLERANCE", "compare_tables", "environment", "write_environment"]

ENVIRONMENT = "environment.json"
PACKAGES = ("lfmdr", "numpy", "scipy", "scikit-learn", "cvxpy", "scs", "clarabel", "pymunk",
            "gymnasium", "joblib", "threadpoolctl")

TOLERANCE: dict[str, float] = {"mpe_abs": 0.002, "mpe_rel": 0.02, "moe_abs": 0.1, "moe_rel": 0.02}
"""A fresh table reproduces a reference when, for every method, its mean MPE (all objects and
non-anchor) is within ``mpe_abs`` metres or ``mpe_rel`` of the reference, and its mean MOE within
``moe_abs`` percentage points or ``moe_rel`` of the reference. Measured spread between machines:
up to 1.2e-4 m and 0.026 points between two (LLE, HLLE, LEM); on a third, with the same package
versions, up to 1.6 % of the MPE and 0.8 % of the MOE (0.12 points of KPCA(POLY)'s 15.4 %), since
a grid search picks another neighbour count when two are nearly tied. The tolerances still
catch a real change."""


def environment() -> dict[str, Any]:
    """Package versions, Python, the platform and the BLAS of this process."""
    versions = {}
    for name in PACKAGES:
        try:
            versions[name] = metadata.version(name)
        except metadata.PackageNotFoundError:
            versions[name] = None
    try:
        from threadpoolctl import threadpool_info

        blas = sorted({f"{i.get('internal_api')} {i.get('version')} ({i.get('architecture')})"
                       for i in threadpool_info() if i.get("user_api") == "blas"})
    except Exception:  # pragma: no cover - diagnostics only
        blas = []
    return {
        "python": sys.version.split()[0],
        "platform": platform.platform(),
        "machine": platform.machine(),
        "processor": platform.processor() or None,
        "cpus": os.cpu_count(),
        "blas": blas,
        "packages": versions,
    }


def write_environment(directory: str | os.PathLike) -> Path:
    """Write ``environment.json`` (atomically) into ``directory``; return its path."""
    path = Path(directory) / ENVIRONMENT
    atomic_write_text(path, json.dumps(environment(), indent=2, sort_keys=True) + "\n")
    return path


def _read_table(path: Path) -> dict[str, dict[str, str]]:
    if not path.is_file():
        raise FileNotFoundError(f"no table at {path} (run lfmdr reproduce first)")
    with open(path, newline="", encoding="utf-8") as fh:
        return {row["method"]: row for row in csv.DictReader(fh)}


def _differs(a: str, b: str, abs_tol: float, rel_tol: float = 0.0) -> bool:
    x, y = float(a), float(b)
    if math.isnan(x) or math.isnan(y):
        return math.isnan(x) != math.isnan(y)
    return not math.isclose(x, y, abs_tol=abs_tol, rel_tol=rel_tol)


def compare_tables(fresh: str | os.PathLike, reference: str | os.PathLike,
                   tolerance: dict[str, float] | None = None) -> list[str]:
    """Differences beyond ``tolerance`` (:data:`TOLERANCE`) between the ``table.csv`` of a fresh
    run directory and a reference one (e.g. ``docs/results/visibility``); empty if it
    reproduces. Methods missing on either side count as differences."""
    tol = {**TOLERANCE, **(tolerance or {})}
    a, b = _read_table(Path(fresh) / "table.csv"), _read_table(Path(reference) / "table.csv")
    problems = [f"{m}: only in {where}" for m, where in
                [(m, "the fresh run") for m in a if m not in b]
                + [(m, "the reference") for m in b if m not in a]]
    for method in (m for m in b if m in a):
        for column, abs_tol, rel_tol in (("mpe_mean", tol["mpe_abs"], tol["mpe_rel"]),
                                         ("mpe_nonanchor_mean", tol["mpe_abs"], tol["mpe_rel"]),
                                         ("moe_mean", tol["moe_abs"], tol["moe_rel"])):
            if _differs(a[method][column], b[method][column], abs_tol, rel_tol):
                problems.append(f"{method}: {column} {a[method][column]} (fresh) vs "
                                f"{b[method][column]} (reference)")
    return problems
