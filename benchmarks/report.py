"""Render the documentation's benchmarks page from the result files committed in the repository.

Every figure on ``docs/benchmarks.md`` comes from a CSV under ``docs/results/`` or
``docs/exploration/``; each table names the command that regenerates its CSV. The page is
generated, not written: edit this script (or rerun a benchmark and commit its CSV), then

    python benchmarks/report.py            # rewrite docs/benchmarks.md
    python benchmarks/report.py --check    # exit 1 if the committed page is not what the CSVs give

``tests/benchmarks/test_benchmarks_page.py`` runs the check, so the page cannot go stale. Standard library
only: the page does not depend on where the package's modules live.
"""

from __future__ import annotations

import argparse
import csv
import math
import statistics
import sys
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PAGE = Path("docs") / "benchmarks.md"


class MissingResultError(FileNotFoundError):
    """A result file the page is rendered from is not in the repository."""


@dataclass(frozen=True)
class Source:
    """One committed result file and the command that regenerates it."""

    path: str  # relative to the repository root
    command: str


# --- the paper's protocol -------------------------------------------------------------------

PROTOCOL = {
    sensor: Source(f"docs/results/{sensor}/table.csv",
                   f"lfmdr reproduce --sensor {sensor} --jobs 2 --out docs/results/{sensor}")
    for sensor in ("visibility", "bearing", "range")
}
PROTOCOL_TITLES = {
    "visibility": "Table 1 — visibility-only mapping",
    "bearing": "Table 2 — bearing-only mapping",
    "range": "Range-only mapping (beyond the paper)",
}
PAPER_NOTES = {
    "visibility": "Paper: Yairi 2007, Table 1 (the graph methods' figures survive only as a "
                  "range).",
    "bearing": "Paper: Yairi 2007, Table 2 (its numbers did not survive the text conversion; "
               "its remarks and its one example map are given).",
    "range": "The paper has no range sensor: this table is ours, on the same protocol.",
}

# --- imperfect sensing ----------------------------------------------------------------------

SENSING = Source("docs/results/sensing/sensing.csv", "python benchmarks/bench_sensing.py --jobs 2")

VIS_BA = [
    (Source("docs/results/vis_ba_tuning.csv",
            "python benchmarks/bench_visibility_adjustment.py --runs 20 --seed 100 "
            "--csv docs/results/vis_ba_tuning.csv"),
     "VIS-BA against its start, tuning layouts (seeds 100..119)"),
    (Source("docs/results/vis_ba_fresh.csv",
            "python benchmarks/bench_visibility_adjustment.py --runs 25 --seed 1000 --settings 0 "
            "--csv docs/results/vis_ba_fresh.csv"),
     "VIS-BA against its start, fresh layouts (seeds 1000..1024)"),
    (Source("docs/results/vis_ba_walk_tuning.csv",
            "python benchmarks/bench_visibility_adjustment.py --runs 20 --seed 100 --walk "
            "--csv docs/results/vis_ba_walk_tuning.csv"),
     "VIS-BA with the walk's continuity prior (VIS-BA-WALK), tuning layouts"),
    (Source("docs/results/vis_ba_walk_tuning_n500.csv",
            "python benchmarks/bench_visibility_adjustment.py --runs 20 --seed 100 --steps 500 "
            "--settings 1 --walk --csv docs/results/vis_ba_walk_tuning_n500.csv"),
     "VIS-BA-WALK after 500 steps, tuning layouts"),
]

# --- exploration ----------------------------------------------------------------------------

EXPLORE = "python benchmarks/bench_exploration.py"
EXPLORATION_CAL_SMA = [
    Source("docs/exploration/baselines.csv",
           f"{EXPLORE} --policies random-walk coverage coverage-scan --method CAL-SMA "
           "--csv docs/exploration/baselines.csv"),
    Source("docs/exploration/rl.csv",
           f"{EXPLORE} --policies rl --method CAL-SMA --csv docs/exploration/rl.csv"),
    Source("docs/exploration/visibility-spread.csv",
           f"{EXPLORE} --sensors visibility --policies random-walk coverage-scan spread "
           "--csv docs/exploration/visibility-spread.csv"),
    Source("docs/exploration/bearing-spread.csv",
           f"{EXPLORE} --sensors bearing --policies spread --method CAL-SMA "
           "--csv docs/exploration/bearing-spread.csv"),
    Source("docs/exploration/visibility-even.csv",
           f"{EXPLORE} --sensors visibility --policies even "
           "--csv docs/exploration/visibility-even.csv"),
    Source("docs/exploration/bearing-even.csv",
           f"{EXPLORE} --sensors bearing --policies even --method CAL-SMA "
           "--csv docs/exploration/bearing-even.csv"),
]
EXPLORATION_OTHER = [
    (Source("docs/exploration/visibility-visba.csv",
            f"{EXPLORE} --sensors visibility --policies random-walk coverage-scan --method VIS-BA "
            "--csv docs/exploration/visibility-visba.csv"),
     "Visibility mapped by VIS-BA (a named method, not the default)"),
    (Source("docs/exploration/visibility-visba-walk.csv",
            f"{EXPLORE} --sensors visibility --policies random-walk coverage-scan "
            "--method VIS-BA-WALK --csv docs/exploration/visibility-visba-walk.csv"),
     "Visibility mapped by VIS-BA-WALK (a named method on perfect histories)"),
    (Source("docs/exploration/bearing-ba.csv",
            f"{EXPLORE} --sensors bearing --policies random-walk coverage coverage-scan rl "
            "--csv docs/exploration/bearing-ba.csv"),
     "Bearing mapped by BEARING-BA (the bearing default)"),
]


# --- reading and formatting -----------------------------------------------------------------

def read_rows(root: Path, source: Source) -> list[dict[str, str]]:
    """The rows of ``source``'s CSV; a clear error naming the file and its command if it is
    missing or empty."""
    path = root / source.path
    if not path.is_file():
        raise MissingResultError(
            f"the benchmarks page is rendered from {source.path}, which is missing; "
            f"regenerate it with: {source.command}"
        )
    with path.open(newline="", encoding="utf-8") as fh:
        rows = list(csv.DictReader(fh))
    if not rows:
        raise MissingResultError(f"{source.path} has no rows; regenerate it with: {source.command}")
    return rows


def number(text: str) -> float:
    """A CSV cell as a float; NaN for an empty or failed cell."""
    try:
        return float(text)
    except (TypeError, ValueError):
        return math.nan


def paper_notation(param: str) -> str:
    """``n_neighbors=8`` -> ``K=8``, ``sigma2=8.0`` -> ``σ²=8.0``, ``degree=2`` -> ``d=2``."""
    names = {"n_neighbors": "K", "sigma2": "σ²", "degree": "d"}
    if param in ("", "-"):
        return "–"
    return ", ".join(
        f"{names.get(k, k)}={v}" for k, v in (p.split("=", 1) for p in param.split(", "))
    )


def pm(mean: str, std: str, digits: int) -> str:
    m, s = number(mean), number(std)
    return "failed" if not math.isfinite(m) else f"{m:.{digits}f} ± {s:.{digits}f}"


def table(header: Sequence[str], rows: Iterable[Sequence[str]]) -> list[str]:
    """A Markdown table."""
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    lines += ["| " + " | ".join(row) + " |" for row in rows]
    return lines


def command(source: Source) -> list[str]:
    return ["```bash", source.command, "```"]


def mean_max(values: list[float]) -> tuple[float, float, int]:
    """Mean and largest of the finite values, and how many there are."""
    ok = [v for v in values if math.isfinite(v)]
    if not ok:
        return math.nan, math.nan, 0
    return statistics.fmean(ok), max(ok), len(ok)


def metres(value: float) -> str:
    """A map error in metres: four decimals, or scientific notation below 0.1 mm."""
    if not math.isfinite(value):
        return "—"
    return f"{value:.1e}" if 0 < abs(value) < 1e-4 else f"{value:.4f}"


# --- sections -------------------------------------------------------------------------------

def protocol_section(root: Path) -> list[str]:
    out = [
        "## The paper's protocol",
        "",
        "5 layouts x 5 start poses, N = 2000 steps of the random walk (paper §4.1). Each method "
        "at its best grid value by mean MPE at N, picked on these runs as the paper does (so "
        "CAL-SMA's best value is listed too; [The paper, reproduced](paper.md) gives it at its "
        "defaults); mean ± "
        "sample std over the runs. MPE over the mapped objects (anchors included, as in the "
        "paper), MOE over all triangles of mapped objects.",
        "",
    ]
    for sensor, source in PROTOCOL.items():
        rows = read_rows(root, source)
        paper = any(r.get("paper_param") or r.get("paper_mpe") or r.get("paper_note")
                    for r in rows)
        header = ["method", "best param", "MPE [m]", "MOE [%]", "MPE non-anchor [m]",
                  "runs (failed)"]
        if paper:
            header += ["paper param", "paper MPE [m]", "paper MOE [%]"]
        body = []
        for r in rows:
            line = [r["method"], paper_notation(r["param"]), pm(r["mpe_mean"], r["mpe_std"], 3),
                    pm(r["moe_mean"], r["moe_std"], 2),
                    pm(r["mpe_nonanchor_mean"], r["mpe_nonanchor_std"], 3),
                    f"{r['runs']} ({r['failed']})"]
            if paper:
                line += [r["paper_param"] or "—", r["paper_mpe"] or r["paper_note"] or "—",
                         r["paper_moe"] or "—"]
            body.append(line)
        out += [f"### {PROTOCOL_TITLES[sensor]}", "", *command(source), "",
                *table(header, body), "", PAPER_NOTES[sensor], ""]
    return out


def sensing_section(root: Path) -> list[str]:
    rows = read_rows(root, SENSING)
    order = {m: i for i, m in reversed(list(enumerate(r["method"] for r in rows)))}
    panels: dict[str, dict[str, dict[str, list[dict[str, str]]]]] = {}
    for r in rows:
        panels.setdefault(r["panel"], {}).setdefault(r["value"], {}).setdefault(
            r["method"], []).append(r)
    summary, details = [], []
    for panel, values in panels.items():
        methods = sorted({m for per in values.values() for m in per}, key=order.get)
        body = []
        for value, per in values.items():
            defaults = sorted({r["default"] for runs in per.values() for r in runs})
            cells, means = [value], {}
            for m in methods:
                runs = per.get(m, [])
                mean, worst, n = mean_max([number(r["mpe_nonanchor"]) for r in runs])
                if not runs:
                    cells.append("")
                elif n < len(runs):
                    cells.append("failed" if n == 0 else f"failed on {len(runs) - n} of {len(runs)}")
                else:
                    means[m] = mean
                    text = f"{mean:.3f} ({worst:.3f})"
                    cells.append(f"**{text}**" if m in defaults else text)
            body.append(cells)
            others = {m: v for m, v in means.items() if m not in defaults}
            best = min(others, key=others.__getitem__) if others else None
            summary.append([
                f"{panel}: {value}", " / ".join(defaults),
                " / ".join(f"{means[d]:.3f}" if d in means else "—" for d in defaults),
                f"{best} {others[best]:.3f}" if best else "—",
            ])
        details += [f"### {panel}", "", "The default for each history in bold.", "",
                    *table(["value", *methods], body), ""]
    return [
        "## Imperfect sensing: the sweep",
        "",
        "Each panel varies one sensing keyword of the paper's world; every method that accepts "
        "the history maps it. 5 fresh layouts per point (a survey, not a choice of defaults: "
        "the defaults were chosen on 25 fresh runs per setting, see "
        "[Imperfect sensing](guide/imperfect.md)), N = 2000. Mean non-anchor MPE [m] over the "
        "runs, the largest run in brackets; \"failed\" where the method refused or failed, "
        "empty where it does not take that kind of history.",
        "",
        *command(SENSING),
        "",
        "![MPE against sensing settings](results/sensing/sensing.png)",
        "",
        "### Summary: the default against the best other method",
        "",
        *table(["setting", "default", "default's MPE [m]", "best other [m]"], summary),
        "",
        *details,
    ]


def vis_ba_section(root: Path) -> list[str]:
    out = [
        "## Visibility maps that estimate the viewpoints (VIS-BA, VIS-BA-WALK)",
        "",
        "N = 2000 unless said, random walk, 50 objects, 4 anchors. Mean / largest non-anchor MPE "
        "[m] over the runs, and the median CPU seconds per map. \"default (start)\" is the map "
        "the adjustment starts from. Each file is the command's output when it was last run; "
        "the choices made from them are in [the lab notes](imperfect-sensing.md).",
        "",
    ]
    for source, title in VIS_BA:
        rows = read_rows(root, source)
        groups: dict[tuple[str, str], list[dict[str, str]]] = {}
        for r in rows:
            groups.setdefault((r["setting"], r["method"]), []).append(r)
        body = []
        for (setting, method), runs in groups.items():
            mean, worst, n = mean_max([number(r["mpe"]) for r in runs])
            cpu = statistics.median(number(r["cpu_s"]) for r in runs)
            body.append([setting, method, str(n), f"{mean:.4f} / {worst:.4f}", f"{cpu:.2f}"])
        out += [f"### {title}", "", *command(source), "",
                *table(["setting", "method", "runs", "MPE mean / largest [m]", "CPU [s]"], body),
                ""]
    return out


UNCERTAINTY = (
    Source("docs/results/uncertainty/simulated.csv",
           "python benchmarks/bench_uncertainty.py --layouts 25 "
           "--sets visibility,bearing,range-bearing,bearing-view90 "
           "--csv docs/results/uncertainty/simulated.csv"),
    Source("docs/results/uncertainty/mrclam.csv",
           "python benchmarks/bench_uncertainty.py --sets "
           "mrclam,mrclam-model,mrclam-anchors,mrclam-floor "
           "--csv docs/results/uncertainty/mrclam.csv"),
    Source("docs/results/uncertainty/calibration.csv",
           "python benchmarks/bench_uncertainty.py --layouts 15 --seed0 13000 "
           "--sets visibility-other-sim --no-inflation "
           "--csv docs/results/uncertainty/calibration.csv"),
    Source("docs/results/uncertainty/calibration-other-sim.csv",
           "python benchmarks/bench_uncertainty.py --layouts 25 --seed0 13100 "
           "--sets visibility-other-sim --csv docs/results/uncertainty/calibration-other-sim.csv"),
    Source("docs/results/uncertainty/calibration-bootstrap.csv",
           "python benchmarks/bench_uncertainty.py --layouts 15 --seed0 13000 "
           "--sets visibility-other-sim --uncertainty bootstrap --no-inflation "
           "--csv docs/results/uncertainty/calibration-bootstrap.csv"),
    Source("docs/results/uncertainty/real.csv",
           "python benchmarks/bench_uncertainty.py --sets "
           "starloc,starloc-model,starloc-anchors,starloc-floor "
           "--csv docs/results/uncertainty/real.csv"),
    Source("docs/results/uncertainty/starloc-s12.csv",
           "python benchmarks/bench_uncertainty.py --sets starloc,starloc-model,starloc-floor "
           "--setups s1,s2 "
           "--csv docs/results/uncertainty/starloc-s12.csv"),
    Source("docs/results/uncertainty/simulated-anchors.csv",
           "python benchmarks/bench_uncertainty.py --layouts 5 --sets bearing,range-bearing "
           "--uncertainty anchors --csv docs/results/uncertainty/simulated-anchors.csv"),
)
UNCERTAINTY_NOTES = {
    "docs/results/uncertainty/simulated.csv": "Fresh layouts of the project's world "
    "(`uncertainty=True`: for the adjustments, the model plus the floor the held-out anchors "
    "estimate).",
    "docs/results/uncertainty/mrclam.csv": "MRCLAM, range and bearing fused; `mrclam`: "
    "`uncertainty=True` (the model plus the floor the held-out anchors estimate); "
    "`mrclam-model`: `uncertainty=\"model\"` (the model alone); `mrclam-inflated`: "
    "the model's covariances times the factor that holds 95 % on the other runs "
    "(leave-one-run-out); "
    "`mrclam-anchors`: `uncertainty=\"anchors\"` (the held-out anchors' check); `mrclam-floor`: "
    "`uncertainty=\"floor\"` (the model plus the systematic floor chosen on STAR-loc s3).",
    "docs/results/uncertainty/calibration.csv": "The body of data the visibility default's "
    "inflation (`JACKKNIFE_INFLATION`, CAL-SMA's linearised jackknife) was chosen on: a second "
    "simulator, run with the factor at 1.",
    "docs/results/uncertainty/calibration-other-sim.csv": "The jackknife's inflation confirmed "
    "on fresh layouts of the second simulator (seeds 13100-13124), with the factor.",
    "docs/results/uncertainty/calibration-bootstrap.csv": "The body of data the bootstrap's "
    "inflation (`BOOTSTRAP_INFLATION`) was chosen on, run with the factor at 1 "
    "(`uncertainty=\"bootstrap\"`; `True` before the jackknife).",
    "docs/results/uncertainty/real.csv": "STAR-loc stereo (s3 sequences, SPATIAL-BA, 3-D) with "
    "`uncertainty=True` (the model plus the held-out anchors' floor), `\"model\"`, "
    "`\"anchors\"` (the covariances checked and scaled by the held-out "
    "anchors, `mappers.core.held_out_anchors`) and `\"floor\"` (the model plus the systematic "
    "floor, `mappers.core.uncertainty.systematic_floor`, whose share was chosen on these maps).",
    "docs/results/uncertainty/starloc-s12.csv": "STAR-loc stereo, setups s1 and s2 (other "
    "calibrations; not used to choose anything): `uncertainty=True`, `\"model\"` and "
    "`\"floor\"`.",
    "docs/results/uncertainty/simulated-anchors.csv": "`uncertainty=\"anchors\"` on fresh "
    "layouts of the project's world (5 layouts, seeds 12000-12004): does the check leave a "
    "calibrated model alone?",
}
UNCERTAINTY_GOALS = {"mrclam": "≥ 0.80", "mrclam-inflated": "≥ 0.80", "mrclam-anchors": "≥ 0.80",
                     "mrclam-floor": "≥ 0.80", "mrclam-model": "≥ 0.80", "starloc": "≥ 0.80",
                     "starloc-anchors": "≥ 0.80", "starloc-floor": "≥ 0.80",
                     "starloc-model": "≥ 0.80"}


def pool_uncertainty(rows: Iterable[dict]) -> list[tuple[str, list[dict], dict[str, float]]]:
    """Per set of ``bench_uncertainty.py``'s rows (CSV cells or its own values), in first-seen
    order: ``(set, its rows, figures)``, the figures pooled over the set's scored landmarks --
    ``coverage`` (share inside their 95 % region), ``sharpness`` (mean RMS radius of the 95 %
    ellipses over the mean position error ``mpe``), ``time_ratio`` (median CPU time of the map
    with its uncertainty over that of the map alone), ``wide`` (landmarks whose region is wider
    than the anchors' extent) and ``sharpness_informative`` (the sharpness of the others; NaN
    when none), the last two over the rows that have them. The benchmark prints these and the
    page shows them: one definition for both."""
    rows = list(rows)
    out = []
    for name in dict.fromkeys(r["set"] for r in rows):
        rs = [r for r in rows if r["set"] == name]
        n = sum(int(r["n_scored"]) for r in rs)
        radius = sum(number(r["rms_radius"]) * int(r["n_scored"]) for r in rs) / n
        err = sum(number(r["mpe"]) * int(r["n_scored"]) for r in rs) / n
        with_wide = [r for r in rs if r.get("n_wide", "") != ""]
        kept = [(int(r["n_scored"]) - int(r["n_wide"]), number(r["rms_radius_informative"]),
                 number(r["mpe_informative"])) for r in with_wide]
        kept = [k for k in kept if k[0] > 0]
        out.append((name, rs, {
            "coverage": sum(int(r["inside"]) for r in rs) / n,
            "sharpness": radius / err,
            "mpe": err,
            "time_ratio": (statistics.median(number(r["cpu_uncertainty"]) for r in rs)
                           / statistics.median(number(r["cpu_map"]) for r in rs)),
            "wide": sum(int(r["n_wide"]) for r in with_wide),
            "sharpness_informative": (sum(k[0] * k[1] for k in kept)
                                      / sum(k[0] * k[2] for k in kept)) if kept else math.nan,
        }))
    return out


def uncertainty_section(root: Path) -> list[str]:
    """Coverage, sharpness and cost of ``build_map(uncertainty=True)`` per set."""
    out = [
        "## Per-landmark uncertainty (`uncertainty=True`)",
        "",
        "Coverage: the share of non-anchor landmarks, pooled over the maps, whose true position "
        "lies inside their 95 % region (goal 0.88-0.99 simulated, ≥ 0.80 real). Sharpness: the "
        "mean RMS radius of the 95 % ellipses over the mean position error (goal ≤ 3; a "
        "calibrated Gaussian gives about 1.95). Wide: landmarks whose 95 % region is wider "
        "than the anchors' extent (\"anywhere on the map\"; one can make the mean meaningless), "
        "and the sharpness of the rest. Time: median CPU time of the map with its "
        "uncertainty over that of the map alone (goal ≤ 1.5). How each is computed: "
        "[the guide](guide/uncertainty.md).",
        "",
    ]
    for source in UNCERTAINTY:
        body = []
        for name, rs, f in pool_uncertainty(read_rows(root, source)):
            # the landmarks' spread beside the anchors', or dashes for a CSV without those columns
            informative = (["—", "—"] if any(not r.get("n_wide") for r in rs)
                           else [str(f["wide"]), f"{f['sharpness_informative']:.2f}"])
            body.append([name, rs[0]["method"], str(len(rs)), f"{f['coverage']:.3f}",
                         UNCERTAINTY_GOALS.get(name, "0.88-0.99"), f"{f['sharpness']:.2f}",
                         *informative, f"{f['mpe']:.4f}", f"{f['time_ratio']:.2f}"])
        out += [UNCERTAINTY_NOTES[source.path], "", *command(source), "",
                *table(["set", "method", "maps", "coverage", "goal", "sharpness",
                        "wide", "sharpness of the rest", "MPE [m]", "time ×"], body), ""]
    return out


STARLOC = Source("docs/results/starloc/starloc.csv",
                  "python benchmarks/bench_starloc.py --out docs/results/starloc/starloc.csv "
                  "--figure docs/guide/starloc_3d.png")
STARLOC_MEDIAN = Source("docs/results/starloc/starloc_visibility_median.csv",
                        "python benchmarks/bench_starloc.py --sensors visibility "
                        "--visibility-method COVIS-3D-MEDIAN "
                        "--out docs/results/starloc/starloc_visibility_median.csv")
STARLOC_SENSORS = ("range-bearing", "bearing", "visibility")
STARLOC_GOALS = {"range-bearing": 0.05, "bearing": 0.10, "visibility": 1.0}


def starloc_section(root: Path) -> list[str]:
    """STAR-loc (issue 34): per sequence, the non-anchor MPE [m] and the share of tags mapped
    for each sensor, the share any map could place (``mappable``), and the
    tags-at-the-anchors'-centroid baseline."""
    rows = read_rows(root, STARLOC)
    by_seq: dict[str, dict[str, dict[str, str]]] = {}
    for r in rows:
        by_seq.setdefault(r["sequence"], {})[r["sensor"]] = r
    median = {r["sequence"]: r for r in read_rows(root, STARLOC_MEDIAN)}

    def cell(r: dict[str, str] | None) -> str:
        if r is None:
            return "-"
        if r["mapped_by"] == "failed":
            return "failed"
        return f"{number(r['mpe']):.3f} ({number(r['mapped']):.0%})"

    def ceiling(runs: dict[str, dict[str, str]]) -> str:
        shares = [r["mappable"] for r in runs.values() if r.get("mappable")]
        return f"{number(shares[0]):.0%}" if shares else "-"

    body = [[seq, *(cell(runs.get(sensor)) for sensor in STARLOC_SENSORS),
             cell(median.get(seq)), ceiling(runs),
             f"{number(next(iter(runs.values()))['centroid_mpe']):.2f}"]
            for seq, runs in sorted(by_seq.items(), key=lambda kv: (kv[0].rsplit("_", 1)[-1],
                                                                     kv[0]))]
    goals = ", ".join(f"{s} <= {g:g} m" for s, g in STARLOC_GOALS.items())
    return [
        "## STAR-loc: 3-D maps of AprilTags from a hand-held stereo camera",
        "",
        "Real data (Dümbgen et al. 2023, arXiv:2309.05518): per sequence, the non-anchor MPE "
        "[m] against the Vicon tag survey and, in brackets, the share of the scored tags "
        "mapped; six anchors (the lowest tag seen in >= 3 image pairs, then farthest-point "
        "order), scored over the other tags seen in >= 3 image pairs. range-bearing and "
        "bearing: SPATIAL-BA; visibility: COVIS-3D. Goals on setup s3: "
        f"{goals}. Setups s1 and s2 have a worse calibration (the data's README). "
        "mappable: the share of the scored tags that a chain of sightings links to three "
        "anchors not on one line, the most a map from the sightings' geometry can place "
        "(`mappers.spatial.anchored`; COVIS-3D places the others by co-observation alone). "
        "COVIS-3D-MEDIAN: the sightings mapped by the opt-in median of four co-observation "
        "maps (`mappers.spatial.SightingsMedian3D`).",
        "",
        *command(STARLOC),
        *command(STARLOC_MEDIAN),
        "",
        *table(["sequence", *STARLOC_SENSORS, "visibility, COVIS-3D-MEDIAN", "mappable",
                "centroid"], body),
        "",
    ]


def exploration_means(root: Path, sources: Sequence[Source]
                      ) -> dict[tuple[str, str, str], dict[int, list[float]]]:
    """(sensor, method, policy) -> steps -> the MPE of each layout, merged over the files as
    ``bench_exploration.py --load`` merges them (a later file's run of a layout replaces an
    earlier one's)."""
    cells: dict[tuple[str, str, str], dict[int, dict[int, float]]] = {}
    for source in sources:
        for r in read_rows(root, source):
            key = (r["sensor"], r["method"], r["policy"])
            cells.setdefault(key, {}).setdefault(int(r["steps"]), {})[int(r["layout"])] = number(
                r["mpe"])
    return {key: {n: list(per.values()) for n, per in steps.items()}
            for key, steps in cells.items()}


def exploration_table(results: dict[tuple[str, str, str], dict[int, list[float]]]) -> list[str]:
    steps = sorted({n for per in results.values() for n in per})
    body = []
    for (sensor, method, policy), per in results.items():
        cells = [sensor, policy, method]
        for n in steps:
            mean, _, count = mean_max(per.get(n, []))
            total = len(per.get(n, []))
            text = metres(mean)
            cells.append(text if count == total else f"{text} ({count} of {total} mapped)")
        body.append(cells)
    body.sort(key=lambda c: (c[0] != "visibility", c[0]))
    return table(["sensor", "policy", "method", *(f"{n:,} steps" for n in steps)], body)


def exploration_section(root: Path) -> list[str]:
    seeds = {r["seed"] for s in EXPLORATION_CAL_SMA for r in read_rows(root, s)}
    out = [
        "## Exploration policies",
        "",
        f"Mean non-anchor MPE [m] against the number of steps, 25 fresh layouts per sensor (seed "
        f"{', '.join(sorted(seeds))}; the same layout and start pose for every policy). Both "
        "sensors mapped with CAL-SMA, which separates the policies (the bearing default, "
        "BEARING-BA, maps every policy's walk exactly: last table).",
        "",
        "![MPE against steps for each exploration policy](exploration.png)",
        "",
        *table(["CSV", "command"], ([f"`{s.path}`", f"`{s.command}`"]
                                    for s in EXPLORATION_CAL_SMA)),
        "",
        "The figure: `" + EXPLORE + " --load "
        + " ".join(s.path for s in EXPLORATION_CAL_SMA) + " --plot docs/exploration.png`.",
        "",
        *exploration_table(exploration_means(root, EXPLORATION_CAL_SMA)),
        "",
    ]
    for source, title in EXPLORATION_OTHER:
        out += [f"### {title}", "", *command(source), "",
                *exploration_table(exploration_means(root, [source])), ""]
    return out


def render(root: Path = ROOT) -> str:
    """The benchmarks page, from the CSV files under ``root``."""
    lines = [
        "<!-- Generated by `python benchmarks/report.py` from the CSV files under docs/results/ "
        "and docs/exploration/. Do not edit: rerun the script. -->",
        "",
        "# Benchmarks",
        "",
        "The figures behind the guide, rendered from the result files committed in the "
        "repository. Each table names the command that regenerates its CSV; "
        "`python benchmarks/report.py` then regenerates this page (a test checks that the page "
        "is what the files give). MPE: mean position error, MOE: mean orientation error; "
        "\"non-anchor\": over the objects whose positions were not given.",
        "",
        *protocol_section(root),
        *sensing_section(root),
        *vis_ba_section(root),
        *uncertainty_section(root),
        *starloc_section(root),
        *exploration_section(root),
    ]
    return "\n".join(lines).rstrip("\n") + "\n"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--check", action="store_true",
                        help="exit 1 if the committed page differs from the rendered one")
    parser.add_argument("--root", type=Path, default=ROOT, help="repository root")
    args = parser.parse_args(argv)
    text = render(args.root)
    page = args.root / PAGE
    if args.check:
        if not page.is_file() or page.read_text(encoding="utf-8") != text:
            print(f"{PAGE} is stale: run python benchmarks/report.py", file=sys.stderr)
            return 1
        print(f"{PAGE} is up to date")
        return 0
    page.write_text(text, encoding="utf-8")
    print(f"wrote {page}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
