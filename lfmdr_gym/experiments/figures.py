"""Tables and PNG figures of the protocol: the paper's Tables 1-2 and figures 4-9, from the rows.

Everything here reads rows of ``results.csv`` (or a map and its history) and draws; nothing maps.
Figures use matplotlib's object API with the Agg canvas, so no display and no global backend
switch are needed (``pip install 'lfmdr[plots]'``).
"""

from __future__ import annotations

import csv
import math
import re
from collections import defaultdict
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from lfmdr_gym.atomic import atomic_savefig, atomic_write, atomic_write_text
from lfmdr_gym.histories.history import History

__all__ = [
    "PAPER",
    "PAPER_EXAMPLES",
    "best_params",
    "paper_notation",
    "plot_curves",
    "plot_estimate",
    "plot_map",
    "plot_views_3d",
    "slug",
    "summarise",
    "write_table",
]

# The paper's figures as far as the text of the paper we have keeps them (Tables 1 and 2,
# figures 6, 7 and 9). Parameters are in the paper's notation. Table 1's text lists every
# method's parameter in order, but MPE and MOE for only three of the five graph-based methods,
# without saying which: those rows carry a "note" instead of "mpe"/"moe".
PAPER: dict[str, dict[str, dict[str, Any]]] = {
    "visibility": {
        "LPCA": {"param": "-", "mpe": 1.055, "moe": 18.19},
        "SMA(UNWGT)": {"param": "-", "mpe": 0.421, "moe": 5.86},
        "SMA(WGT)": {"param": "K=5", "mpe": 0.206, "moe": 4.83},
        "KPCA(GAUS)": {"param": "σ²=0.5", "mpe": 0.926, "moe": 23.29},
        "KPCA(POLY)": {"param": "d=8", "mpe": 0.953, "moe": 27.03},
        "ISOMAP": {"param": "K=6", "note": "0.18-0.24"},
        "LLE": {"param": "K=8", "note": "0.18-0.24"},
        "LEM": {"param": "K=6", "note": "0.18-0.24"},
        "HLLE": {"param": "K=8", "note": "0.18-0.24"},
        "SDE": {"param": "K=7", "note": "best, >= 0.18"},
    },
    "bearing": {
        "LPCA": {"note": "better than LLE and LEM"},
        "HLLE": {"note": "often failed to run"},
        "SMA(WGT)": {"param": "K=8", "note": "example map: 0.0512 m, 1.10 %"},
    },
}
PAPER_SOURCE = {
    "visibility": "Yairi 2007, Table 1. The text of the paper we have gives every method's "
                  "parameter, but MPE and MOE for only three of its five graph-based methods "
                  "(0.177, 0.241 and 0.192 m) without saying which method each belongs to, so "
                  "their rows give the range; its text says SDE's error is the lowest",
    "bearing": "Yairi 2007, Table 2, whose numbers are missing from the text of the paper we "
               "have; the remarks are from its §4.4.2",
}
"""The last line of ``table.md``: where the paper's column comes from, and what it lacks."""

PAPER_EXAMPLES: dict[str, tuple[str, ...]] = {
    "visibility": ("LPCA", "SDE"),  # figures 6 and 7
    "bearing": ("SMA(WGT)",),  # figure 9
}
"""Methods of the paper's example maps per sensor."""

# The paper's split of its curves: figure 4 (global methods + ISOMAP), figure 5 (local methods).
_PANELS = (
    ("LPCA", "SMA(UNWGT)", "SMA(WGT)", "KPCA(GAUS)", "KPCA(POLY)", "ISOMAP"),
    ("LPCA", "LLE", "LEM", "HLLE", "SDE"),
)


def slug(method: str) -> str:
    """A file-name-safe form of a method label: ``"SMA(WGT)"`` -> ``"sma_wgt"``."""
    return re.sub(r"[^a-z0-9]+", "_", method.lower()).strip("_")


def _figure(width: float, height: float) -> Any:
    try:
        from matplotlib.backends.backend_agg import FigureCanvasAgg
        from matplotlib.figure import Figure
    except ImportError as exc:  # pragma: no cover - optional extra
        raise ValueError("figures need matplotlib: pip install 'lfmdr[plots]'") from exc
    fig = Figure(figsize=(width, height), dpi=110, layout="constrained")
    FigureCanvasAgg(fig)
    return fig


def _mean_std(values: Sequence[float]) -> tuple[float, float]:
    """Mean and sample standard deviation (0 for a single run) of the finite values."""
    arr = np.asarray([v for v in values if math.isfinite(v)], dtype=float)
    if arr.size == 0:
        return math.nan, math.nan
    return float(arr.mean()), float(arr.std(ddof=1)) if arr.size > 1 else 0.0


def summarise(rows: Sequence[Mapping[str, Any]], n_steps: int) -> dict[str, dict[str, dict[str, Any]]]:
    """method -> param -> mean/std of MPE, MOE, non-anchor MPE over the runs at ``n_steps``,
    with ``runs`` (successful) and ``failed`` counts."""
    groups: dict[tuple[str, str], list[Mapping[str, Any]]] = defaultdict(list)
    for r in rows:
        if r["n_steps"] == n_steps:
            groups[(r["method"], r["param"])].append(r)
    out: dict[str, dict[str, dict[str, Any]]] = defaultdict(dict)
    for (method, param), members in groups.items():
        ok = [r for r in members if not r["error"] and math.isfinite(r["mpe"])]
        stats: dict[str, Any] = {"param": param, "runs": len(ok), "failed": len(members) - len(ok)}
        for col in ("mpe", "moe", "mpe_nonanchor"):
            stats[f"{col}_mean"], stats[f"{col}_std"] = _mean_std([r[col] for r in ok])
        out[method][param] = stats
    return dict(out)


def best_params(rows: Sequence[Mapping[str, Any]], n_steps: int) -> dict[str, dict[str, Any]]:
    """Per method, the parameter with the lowest mean MPE at ``n_steps`` (paper §4.1).

    A parameter that failed on fewer runs wins over one that failed on more: a mean over the
    runs a method survived would otherwise flatter it.
    """
    best = {}
    for method, by_param in summarise(rows, n_steps).items():
        def rank(s: dict[str, Any]) -> tuple[float, float]:
            mean = s["mpe_mean"]
            return (s["failed"], mean if math.isfinite(mean) else math.inf)

        best[method] = min(by_param.values(), key=rank)
    return best


_PAPER_NAMES = (("n_neighbors=", "K="), ("degree=", "d="), ("sigma2=", "σ²="))


def paper_notation(param: str) -> str:
    """``"n_neighbors=5"`` -> ``"K=5"``: parameter labels in the paper's notation, for tables."""
    for ours, theirs in _PAPER_NAMES:
        param = param.replace(ours, theirs)
    return param


def _legend(method: str, param: str) -> str:
    return method if param == "-" else f"{method} ({paper_notation(param)})"


def _pm(mean: float, std: float, digits: int) -> str:
    if not math.isfinite(mean):
        return "failed"
    return f"{mean:.{digits}f} ± {std:.{digits}f}"


def write_table(
    rows: Sequence[Mapping[str, Any]],
    out: Path,
    *,
    sensor: str,
    n_steps: int,
    methods: Sequence[str],
    defaults: Mapping[str, str] | None = None,
    n_runs: int | None = None,
) -> list[Path]:
    """``table.csv`` and ``table.md``: per method its best parameter at N = ``n_steps`` with
    mean ± std of MPE and MOE over the runs, beside the paper's figures (Tables 1 and 2)."""
    out = Path(out)
    best = best_params(rows, n_steps)
    paper = PAPER.get(sensor, {})
    cols = ["method", "param", "runs", "failed", "mpe_mean", "mpe_std", "moe_mean", "moe_std",
            "mpe_nonanchor_mean", "mpe_nonanchor_std", "default_param", "paper_param",
            "paper_mpe", "paper_moe", "paper_note"]
    table = []
    for m in methods:
        if m not in best:
            continue
        b, p = best[m], paper.get(m, {})
        table.append({
            "method": m, **{k: b[k] for k in cols[1:10]},
            "default_param": (defaults or {}).get(m, ""),
            "paper_param": p.get("param", ""), "paper_mpe": p.get("mpe", ""),
            "paper_moe": p.get("moe", ""), "paper_note": p.get("note", ""),
        })
    csv_path = out / "table.csv"
    with atomic_write(csv_path) as fh:
        writer = csv.DictWriter(fh, fieldnames=cols, lineterminator="\n")
        writer.writeheader()
        for row in table:
            writer.writerow({k: (f"{v:.6g}" if isinstance(v, float) else v) for k, v in row.items()})

    runs = f"{n_runs} runs" if n_runs else "all runs"
    lines = [
        f"# {sensor.capitalize()}-only mapping: final map errors at N = {n_steps} ({runs})",
        "",
        "Best parameter per method by mean MPE at the last checkpoint; mean ± sample std over the "
        "runs. MPE over the mapped objects (anchors included, as in the paper), MOE over all "
        "triangles of mapped objects.",
        "",
        "| method | best param | MPE [m] | MOE [%] | MPE non-anchor [m] | runs (failed) "
        + ("| paper param | paper MPE [m] | paper MOE [%] |" if sensor in PAPER_SOURCE else "|"),
        "|---|---|---|---|---|---|" + ("---|---|---|" if sensor in PAPER_SOURCE else ""),
    ]
    for r in table:
        pm = r["paper_mpe"] if r["paper_mpe"] != "" else r["paper_note"]
        line = (
            f"| {r['method']} | {paper_notation(r['param'])} "
            f"| {_pm(r['mpe_mean'], r['mpe_std'], 3)} "
            f"| {_pm(r['moe_mean'], r['moe_std'], 2)} "
            f"| {_pm(r['mpe_nonanchor_mean'], r['mpe_nonanchor_std'], 3)} "
            f"| {r['runs']} ({r['failed']}) |"
        )
        if sensor in PAPER_SOURCE:
            line += f" {r['paper_param'] or '—'} | {pm or '—'} | {r['paper_moe'] or '—'} |"
        lines.append(line)
    source = PAPER_SOURCE.get(sensor)
    lines += ["", f"Paper: {source}." if source else
              f"The paper has no {sensor} sensor: this table is ours (same protocol).", ""]
    md_path = out / "table.md"
    atomic_write_text(md_path, "\n".join(lines))
    return [csv_path, md_path]


def plot_curves(
    rows: Sequence[Mapping[str, Any]],
    path: Path,
    *,
    sensor: str,
    methods: Sequence[str],
    curve_params: Mapping[str, str],
) -> Path:
    """MPE against N for every method at its curve parameter: mean over runs, ±1 std bars.

    Two panels in the paper's grouping (figures 4/5; figure 8 for bearing), LPCA in both.
    """
    series: dict[str, dict[int, list[float]]] = defaultdict(lambda: defaultdict(list))
    for r in rows:
        if r["param"] == curve_params.get(r["method"]) and not r["error"] and math.isfinite(r["mpe"]):
            series[r["method"]][r["n_steps"]].append(r["mpe"])
    panels = [[m for m in group if m in methods] for group in _PANELS]
    rest = [m for m in methods if not any(m in g for g in _PANELS)]
    panels[1] += rest
    panels = [p for p in panels if p]
    fig = _figure(6.0 * len(panels), 4.5)
    axes = fig.subplots(1, len(panels), squeeze=False)[0]
    for ax, group in zip(axes, panels, strict=True):
        for m in group:
            if m not in series:
                continue
            ns = sorted(series[m])
            stats = [_mean_std(series[m][n]) for n in ns]
            ax.errorbar(ns, [s[0] for s in stats], yerr=[s[1] for s in stats], marker="o",
                        capsize=3, label=_legend(m, curve_params.get(m, "-")))
        ax.set_xlabel("N (steps)")
        ax.set_ylabel("mean position error [m]")
        ax.set_ylim(bottom=0)
        ax.grid(alpha=0.3)
        if ax.get_legend_handles_labels()[0]:  # (a panel whose methods all failed has none)
            ax.legend(fontsize=8)
    fig.suptitle(f"{sensor.capitalize()}-only mapping: MPE against the number of observations")
    atomic_savefig(fig, path)
    return Path(path)


def plot_map(positions: np.ndarray, history: History, path: Path, *, title: str = "",
             notes: Sequence[str] = (), covariances: np.ndarray | None = None) -> Path:
    """An example map (paper figures 6, 7, 9) of a history: see :func:`plot_estimate`."""
    return plot_estimate(positions, history.object_positions, history.anchor_ids, path,
                         title=title, trail=history.robot_poses, notes=notes,
                         covariances=covariances)


# Characters per line of the map figure's title (fontsize 9) and notes (fontsize 7) on its
# 6-inch width, and the height [in] of one line of each.
_TITLE_CHARS, _NOTE_CHARS = 80, 100
_TITLE_LINE, _NOTE_LINE = 9 * 1.25 / 72, 7 * 1.25 / 72


def _wrapped(texts: Sequence[str], width: int, prefix: str = "") -> list[str]:
    """Each text wrapped to ``width`` characters (its own line breaks kept), ``prefix`` before
    its first line and its continuation lines indented."""
    import textwrap

    indent = "    " if prefix else ""
    lines: list[str] = []
    for text in texts:
        for k, part in enumerate(str(text).splitlines() or [""]):
            lines += textwrap.wrap(part, width, initial_indent=prefix if k == 0 else indent,
                                   subsequent_indent=indent) or [""]
    return lines


def _draw_points(ax: Any, est: np.ndarray, truth: np.ndarray, anchors: np.ndarray,
                 axes: tuple[int, int] = (0, 1)) -> None:
    """Onto ``ax``, the plane ``axes`` of a map: a line from each known truth to its estimate,
    the truth as circles, the estimates as crosses, the anchors' truth as squares."""
    a, b = axes
    known = np.all(np.isfinite(truth), axis=1)
    mapped = np.all(np.isfinite(est), axis=1)
    for t, e in zip(truth[known & mapped], est[known & mapped], strict=True):
        ax.plot([t[a], e[a]], [t[b], e[b]], color="tab:red", lw=0.8)
    for rows, pts, style in (
        (known & ~anchors, truth, {"s": 22, "facecolors": "none", "edgecolors": "k",
                                   "label": "true"}),
        (mapped & ~anchors, est, {"s": 16, "marker": "x", "color": "tab:blue",
                                  "label": "estimate"}),
        (known & anchors, truth, {"s": 60, "marker": "s", "facecolors": "none",
                                  "edgecolors": "tab:green", "label": "anchor"}),
    ):
        ax.scatter(pts[rows, a], pts[rows, b], **style)


def _axes_in_metres(ax: Any, horizontal: str, vertical: str) -> None:
    """Equal scales, the two axes named in metres, a light grid."""
    ax.set_aspect("equal")
    ax.set_xlabel(f"{horizontal} [m]")
    ax.set_ylabel(f"{vertical} [m]")
    ax.grid(alpha=0.3)


def plot_estimate(
    positions: np.ndarray,
    truth: np.ndarray,
    anchor_ids: Sequence[int] | np.ndarray,
    path: Path,
    *,
    title: str = "",
    labels: Sequence[int] | np.ndarray | None = None,
    trail: np.ndarray | None = None,
    notes: Sequence[str] = (),
    covariances: np.ndarray | None = None,
) -> Path:
    """True positions, estimates, and a line between (paper figures 6, 7, 9), saved atomically.

    Anchors are drawn as squares; unmapped objects (NaN estimates) as grey crosses at the truth;
    objects are labelled by ``labels`` (default: their index) at their truth, or at their
    estimate where the truth is unknown (NaN: a log mapped without ground truth); ``trail``
    (N, >=2) draws the robot's path faintly underneath, when the data has one. The title is wrapped to the
    figure's width; ``notes`` (e.g. the map's warnings) are written in full below the plot,
    each wrapped, and the figure grows to hold them. ``covariances`` ((M, 2, 2),
    ``Map.covariances``) draws each estimate's 95 % ellipse
    (:func:`lfmdr_gym.render.draw_ellipses`).
    """
    est = np.asarray(positions, dtype=float)
    truth = np.asarray(truth, dtype=float)
    anchors = np.zeros(len(truth), dtype=bool)
    anchors[np.asarray(anchor_ids, dtype=int)] = True
    labels = range(len(truth)) if labels is None else labels
    span = np.nanmax(truth, axis=0) - np.nanmin(truth, axis=0)
    title_lines = _wrapped([title], _TITLE_CHARS) if title else []
    note_lines = _wrapped(notes, _NOTE_CHARS, prefix="warning: ")
    extra = max(len(title_lines) - 1, 0) * _TITLE_LINE + len(note_lines) * _NOTE_LINE
    height = float(np.clip(6.0 * span[1] / max(span[0], 1e-9), 4.0, 9.0)) + 0.2
    fig = _figure(6.0, height + extra + (0.15 if note_lines else 0.0))
    ax = fig.add_subplot()
    known = np.all(np.isfinite(truth), axis=1)
    mapped = np.all(np.isfinite(est), axis=1)
    _draw_points(ax, est, truth, anchors)
    if covariances is not None:
        from lfmdr_gym.render import draw_ellipses

        draw_ellipses(ax, est, covariances)
    if np.any(known & ~mapped):
        ax.scatter(*truth[known & ~mapped].T, s=40, marker="x", color="grey", label="unmapped")
    if trail is not None:
        ax.plot(*np.asarray(trail)[:, :2].T, color="0.85", lw=0.4, zorder=0)
    for j, label in enumerate(labels):  # at the truth; where it is unknown, at the estimate
        if known[j] or mapped[j]:
            ax.annotate(str(label), truth[j] if known[j] else est[j], fontsize=6, color="0.4",
                        xytext=(2, 2), textcoords="offset points")
    _axes_in_metres(ax, "x", "y")
    ax.legend(fontsize=8, loc="upper right")
    if title_lines:
        ax.set_title("\n".join(title_lines), fontsize=9)
    if note_lines:  # below the plot, left-aligned; constrained layout keeps room for it
        fig.supxlabel("\n".join(note_lines), fontsize=7, x=0.01, ha="left",
                      multialignment="left", color="tab:red")
    atomic_savefig(fig, path)
    return Path(path)



_VIEWS_3D = (("top", 0, 1), ("front", 0, 2), ("side", 1, 2))
"""The three orthographic views of a 3-D map: name, horizontal axis, vertical axis."""


def plot_views_3d(positions: np.ndarray, truth: np.ndarray, anchor_ids: Sequence[int] | np.ndarray,
                  path: Path, *, title: str = "", notes: Sequence[str] = (),
                  covariances: np.ndarray | None = None) -> Path:
    """A 3-D map as three orthographic views (top: x-y, front: x-z, side: y-z), saved atomically.

    As :func:`plot_estimate` in each view: the truth as circles, the estimates as crosses with a
    line to their truth, anchors as squares, unmapped objects (NaN estimates) as grey crosses at
    the truth; a NaN truth row (a landmark without ground truth) draws its estimate alone.
    ``positions`` and ``truth`` are (M, 3); ``notes`` are written below the views.
    ``covariances`` ((M, 3, 3), ``Map.covariances``) draws in each view each estimate's 95 %
    ellipse of its position in that plane (the covariance's 2 x 2 block of the view's axes).
    """
    est = np.asarray(positions, dtype=float)
    truth = np.asarray(truth, dtype=float)
    if est.ndim != 2 or est.shape[1] != 3 or truth.shape != est.shape:
        raise ValueError(f"plot_views_3d draws (M, 3) positions and truth of the same shape, got "
                         f"{est.shape} and {truth.shape}")
    anchors = np.zeros(len(truth), dtype=bool)
    anchors[np.asarray(anchor_ids, dtype=int)] = True
    lost = np.all(np.isfinite(truth), axis=1) & ~np.all(np.isfinite(est), axis=1)
    note_lines = _wrapped(notes, 2 * _NOTE_CHARS, prefix="warning: ")
    fig = _figure(13.0, 4.6 + len(note_lines) * _NOTE_LINE)
    axes = fig.subplots(1, 3)
    if covariances is not None:
        from lfmdr_gym.render import draw_ellipses
    for ax, (name, a, b) in zip(axes, _VIEWS_3D, strict=True):
        _draw_points(ax, est, truth, anchors, (a, b))
        if covariances is not None:
            plane = np.asarray(covariances, dtype=float)[:, [a, b]][:, :, [a, b]]
            draw_ellipses(ax, est[:, [a, b]], plane)
        if lost.any():
            ax.scatter(truth[lost, a], truth[lost, b], s=40, marker="x", color="grey",
                       label="unmapped")
        ax.set_title(f"{name} ({'xyz'[a]}, {'xyz'[b]})", fontsize=9)
        _axes_in_metres(ax, "xyz"[a], "xyz"[b])
    axes[0].legend(fontsize=8, loc="best")
    if title:
        fig.suptitle("\n".join(_wrapped([title], 2 * _TITLE_CHARS)), fontsize=10)
    if note_lines:
        fig.supxlabel("\n".join(note_lines), fontsize=7, x=0.01, ha="left",
                      multialignment="left", color="tab:red")
    atomic_savefig(fig, path, bbox_inches="tight")  # equal-aspect views: keep labels
    return Path(path)
