"""The ``lfmdr`` command: parse, call one library function, print. No logic of its own.

Subcommands: ``reproduce`` (the paper's protocol), ``run`` (one episode mapped at its
checkpoints), ``map`` (map a saved history or an observation log), ``collect`` (record a
random-walk episode), ``mrclam`` (map a real MRCLAM run), ``compare`` (check a fresh table
against a reference) and ``convert`` (a dataset or a ROS bag to an observation table); ``map``
and ``convert`` live in :mod:`lfmdr_gym.cli_map`. Bad options exit with status 2 and a one-line
message; Ctrl-C exits with 130 after saying how to resume.
"""

from __future__ import annotations

import argparse
import signal
import sys
from collections.abc import Sequence
from typing import Any

from lfmdr_gym.cli_common import (
    Formatter,
    add_command,
    add_method_options,
    add_sensor_option,
    positive_int,
    print_warnings,
)
from lfmdr_gym.cli_map import add_convert, add_map

_POLICY_HELP = ("exploration policy, a name of lfmdr_gym.POLICIES (random-walk, coverage, "
                "coverage-scan, rl, spread, even)")

EXIT_USAGE = 2
EXIT_INTERRUPTED = 130

_DESCRIPTION = """\
Localisation-free mapping by dimensionality reduction (Yairi 2007): a robot's per-object
observation histories are embedded in the plane and aligned to a few anchors; no pose is estimated.
"""


def _jobs(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a positive integer or -1, got {text!r}") from None
    if value == 0 or value < -1:
        raise argparse.ArgumentTypeError(f"expected a positive integer or -1 (all cores), got {value}")
    return value


def _csv_list(text: str) -> list[str]:
    return [t.strip() for t in text.split(",") if t.strip()]


def _int_list(text: str) -> list[int]:
    try:
        return [int(t) for t in _csv_list(text)]
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected numbers like 1,2,3, got {text!r}") from None


def _method_list(values: Sequence[str] | None) -> list[str] | None:
    if not values:
        return None
    return [name for v in values for name in _csv_list(v)]


_ENV_ID_HELP = ("environment id, one of lfmdr_gym.ENV_IDS (LFMDR-Visibility-v0, LFMDR-Bearing-v0, "
                "LFMDR-Range-v0, LFMDR-RangeBearing-v0, LFMDR-VisibilityBearing-v0, "
                "LFMDR-Camera-v0) or lfmdr_gym.ENV_IDS_3D (LFMDR-Camera3D-v0: tags at heights, "
                "a 3-D history; --env-kw sensor=bearing|visibility)")


def _version() -> str:
    """The installed package's version (its metadata), or a note that it is not installed."""
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("lfmdr")
    except PackageNotFoundError:
        return "(version unknown: the lfmdr package is not installed)"


def _add_env_keywords(p: argparse.ArgumentParser) -> None:
    """``--env-kw NAME=VALUE``: the env keywords, in every command that makes an env (``--env``
    is always an env id)."""
    p.add_argument("--env-kw", action="append", default=None, metavar="NAME=VALUE",
                   dest="env_kwargs",
                   help="env keyword (repeatable), e.g. fov_deg=90, max_range=1.5, "
                        "bearing_noise_deg=2, miss_rate=0.5, line_of_sight=true: imperfect "
                        "sensing (see LFMDREnv); values are read as numbers, true/false or none")


def _add_episode_options(p: argparse.ArgumentParser, env_help: str | None) -> None:
    """``--env`` (when ``env_help`` is given: an env id) and ``--steps``, the episode to run."""
    if env_help is not None:
        p.add_argument("--env", default="LFMDR-Visibility-v0", metavar="ID", help=env_help)
    p.add_argument("--steps", type=positive_int, default=2000, help="episode length N")


def _add_seed_option(p: argparse.ArgumentParser, what: str) -> None:
    p.add_argument("--seed", type=int, default=0, help=what)


def _add_walk_options(p: argparse.ArgumentParser, env_help: str) -> None:
    """The episode of a command that walks one policy through one env: ``--env`` (an env id),
    ``--steps``, ``--seed``, ``--env-kw`` and ``--policy``."""
    _add_episode_options(p, env_help)
    _add_seed_option(p, "seed of layout, start pose and walk")
    _add_env_keywords(p)
    p.add_argument("--policy", default="random-walk", metavar="NAME", help=_POLICY_HELP)


def _add_every_option(p: argparse.ArgumentParser, otherwise: str) -> None:
    p.add_argument("--every", type=positive_int, default=None,
                   help="checkpoint interval; must divide --steps (default: 500 for visibility, "
                        + otherwise + ")")


class _OldEnvKeyword(argparse.Action):
    """``reproduce --env NAME=VALUE``, the older spelling of ``--env-kw``: still accepted, with a
    deprecation message naming the new flag, in argparse's style on stderr (everywhere else
    ``--env`` is an env id)."""

    def __call__(self, parser: argparse.ArgumentParser, namespace: argparse.Namespace,
                 values: Any, option_string: str | None = None) -> None:
        if "=" not in str(values):
            parser.error(f"argument --env: reproduce takes no env id ({values!r}): its env is "
                         "chosen by --sensor; env keywords are given as --env-kw NAME=VALUE")
        print(f"{parser.prog}: warning: --env {values} is deprecated, write --env-kw {values} "
              "(--env is an env id in the other commands)", file=sys.stderr)
        setattr(namespace, self.dest, [*(getattr(namespace, self.dest, None) or []), values])


def _add_reproduce(sub: Any) -> None:
    p = add_command(
        sub, "reproduce", "run the paper's protocol and write results.csv, table.md/csv and figures",
        "Run the paper's protocol (§4.1): every (layout, pose) episode with the random-walk "
        "agent; at the last checkpoint every method over its whole parameter grid, at every "
        "checkpoint each method's default (the paper's optimum). Writes into --out: "
        "results.csv (one row per sensor, layout, pose, method, param, n_steps), table.md and "
        "table.csv (best parameter per method, mean ± std of MPE and MOE, beside the paper), "
        "mpe_vs_n.png (figures 4/5/8), map_*.png example maps (figures 6/7/9) and "
        "environment.json (package versions and machine).",
        "Safe to interrupt: each result is saved as soon as it exists; rerunning the same "
        "command resumes where it stopped, after Ctrl-C or a kill alike, and computes again "
        "any unit whose mapper failed. Other settings on the same --out are refused. "
        "Episodes are cached in --out/histories.",
        "With --env-kw keywords that limit sensing (fov_deg, max_range, noise, dropouts) the "
        "histories are masked and the methods default to those that map masked histories.",
    )
    add_sensor_option(p, "visibility (Table 1), bearing (Table 2) or range (beyond the paper: "
                          "the same protocol with a range sensor)")
    p.add_argument("--layouts", type=positive_int, default=5, help="random object layouts")
    p.add_argument("--poses", type=positive_int, default=5,
                   help="random start poses per layout (runs = layouts x poses)")
    _add_episode_options(p, None)
    _add_every_option(p, "200 otherwise")
    p.add_argument("--methods", nargs="+", default=None, metavar="METHOD",
                   help="registered methods that map the sensor's histories, space- or "
                        "comma-separated, case-insensitive (default: every method made for "
                        "complete histories)")
    _add_seed_option(p, "base seed of layouts and poses")
    _add_env_keywords(p)
    p.add_argument("--env", action=_OldEnvKeyword, dest="env_kwargs", metavar="NAME=VALUE",
                   help=argparse.SUPPRESS)  # the older spelling of --env-kw (with a notice)
    p.add_argument("--jobs", type=_jobs, default=1,
                   help="worker processes on this machine (-1: all cores); BLAS is kept to one "
                        "thread per worker")
    p.add_argument("--scheduler", default=None, metavar="ADDRESS",
                   help="run the work on an existing Dask distributed cluster at ADDRESS "
                        "(e.g. tcp://host:8786) instead of local processes")
    p.add_argument("--out", default=None, metavar="DIR",
                   help="run directory (default: results/<sensor>); reuse it to resume")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.set_defaults(handler=_cmd_reproduce)


def _add_run(sub: Any) -> None:
    p = add_command(
        sub, "run", "one episode, mapped at its checkpoints, scores printed, a map figure",
        "Collect one random-walk episode, map it with one method at every checkpoint, print "
        "MPE and MOE, and write history.npz, scores.csv, map.csv and map.png into --out."
    )
    _add_walk_options(p, _ENV_ID_HELP)
    add_method_options(p, "the default for the env's histories, as build_map chooses")
    _add_every_option(p, "200 otherwise, plus N itself")
    p.add_argument("--out", default="lfmdr-run", metavar="DIR", help="output directory")
    p.add_argument("--online", action="store_true",
                   help="map online as the robot moves (mappers.OnlineMapper, updated every 10 "
                        "steps); writes history.npz, scores.csv (the online map's error at every "
                        "update), map.csv and map.png (the final online map) and live.gif (the "
                        "growing map beside the robot; needs matplotlib: pip install "
                        "'lfmdr[plots]')")
    p.set_defaults(handler=_cmd_run)


def _add_collect(sub: Any) -> None:
    p = add_command(
        sub, "collect", "record one episode as a history file and summarise it",
        "Run one episode with an exploration policy (default: the paper's random walk) and "
        "save what the robot sensed (and the ground truth for scoring) as a History .npz; "
        "print a summary."
    )
    _add_walk_options(p, _ENV_ID_HELP + "; a fused one (LFMDR-RangeBearing-v0, "
                      "LFMDR-VisibilityBearing-v0, LFMDR-Camera-v0) records a fused history")
    p.add_argument("--out", required=True, metavar="FILE.npz", help="history file to write")
    p.set_defaults(handler=_cmd_collect)


def _add_mrclam(sub: Any) -> None:
    p = add_command(
        sub, "mrclam", "map the landmarks of a real UTIAS MRCLAM run",
        "Map the landmarks of an MRCLAM run directory from the robots' logged sightings "
        "(no localisation); writes DIR/map.csv (subject, x, y) and a figure, and prints MPE "
        "and MOE over the non-anchor landmarks."
    )
    p.add_argument("run_dir", metavar="RUN_DIR", help="an MRCLAM run directory")
    add_sensor_option(p, "which measurement to map from (range-bearing: both measurements of "
                          "every sighting, fused)", fused=("range-bearing",))
    p.add_argument("--robots", type=_int_list, default=None, metavar="1,2,3,4,5",
                   help="robot subject numbers whose logs are used (default: all five)")
    add_method_options(p, "COVIS-ENSEMBLE for visibility and bearing, RANGE-QUANTILE for "
                           "range, LOC-SMA for range-bearing; 'naive' is SMA(UNWGT) with "
                           "--zero-fill")
    p.add_argument("--zero-fill", action="store_true",
                   help="map the history with unobserved entries as zeros and no mask (the "
                        "paper's pipeline on logged data), so methods for complete histories apply")
    p.add_argument("--anchors", type=_int_list, default=None, metavar="S1,S2,S3,S4",
                   help="landmark subject numbers used as anchors (default: the 4 nearest the "
                        "corners of the landmarks' bounding box)")
    p.add_argument("--bin-width", type=float, default=None, metavar="SECONDS",
                   help="width of the time bins of the histories (default: the sensor's default)")
    p.add_argument("--groundtruth-fixes", choices=["known", "detect", "none"], default="known",
                   help="known: swap back documented ground-truth errors (DS1's subjects 11 and "
                        "17); detect: also those a range+bearing check finds; none: use the file "
                        "as given (problems still warn)")
    p.add_argument("--out", default="lfmdr-mrclam", metavar="DIR",
                   help="output directory for map.csv and map.png")
    p.set_defaults(handler=_cmd_mrclam)


def _add_compare(sub: Any) -> None:
    from lfmdr_gym.experiments.reproducibility import TOLERANCE

    p = add_command(
        sub, "compare", "check that a fresh `lfmdr reproduce` run reproduces a reference table",
        "Compare the table.csv of a run directory with a reference one (e.g. "
        "docs/results/visibility): every method's mean MPE within --mpe-abs metres or "
        "--mpe-rel of the reference, and its mean MOE within --moe-abs percentage points or "
        "--moe-rel of the reference. "
        "Exit status 0 when it reproduces, 1 otherwise."
    )
    p.add_argument("fresh", metavar="RUN_DIR", help="a directory written by lfmdr reproduce")
    p.add_argument("reference", metavar="REFERENCE_DIR", help="e.g. docs/results/visibility")
    p.add_argument("--mpe-abs", type=float, default=TOLERANCE["mpe_abs"], help="metres")
    p.add_argument("--mpe-rel", type=float, default=TOLERANCE["mpe_rel"], help="fraction")
    p.add_argument("--moe-abs", type=float, default=TOLERANCE["moe_abs"], help="percentage points")
    p.add_argument("--moe-rel", type=float, default=TOLERANCE["moe_rel"], help="fraction")
    p.set_defaults(handler=_cmd_compare)


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of ``lfmdr`` (exposed for tests and documentation)."""
    parser = argparse.ArgumentParser(prog="lfmdr", description=_DESCRIPTION, formatter_class=Formatter)
    parser.add_argument("--version", action="version", version=f"lfmdr {_version()}",
                        help="print the installed version and exit")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
    for add in (_add_reproduce, _add_run, add_map, _add_collect, _add_mrclam, _add_compare,
                add_convert):
        add(sub)
    return parser


# --------------------------------------------------------------------------- handlers
def _cmd_reproduce(args: argparse.Namespace) -> int:
    from lfmdr_gym.experiments.env_settings import parse_env_kwargs
    from lfmdr_gym.experiments.protocol import ProtocolConfig, run_protocol

    config = ProtocolConfig(
        sensor=args.sensor, layouts=args.layouts, poses=args.poses, steps=args.steps,
        every=args.every, methods=_method_list(args.methods), seed=args.seed,
        env_kwargs=parse_env_kwargs(args.env_kwargs),
    )
    out = args.out or f"results/{args.sensor}"
    try:
        summary = run_protocol(config, out, jobs=args.jobs, scheduler=args.scheduler,
                               progress=not args.no_progress)
    except KeyboardInterrupt:
        print(f"\ninterrupted: finished results are saved in {out}; rerun the same command to "
              "resume", file=sys.stderr)
        return EXIT_INTERRUPTED
    print(summary)
    table = summary.out / "table.md"
    if table.exists():
        print()
        print(table.read_text(encoding="utf-8"))
    return 0


def _print_scores(rows: Sequence[dict[str, Any]]) -> None:
    print(f"{'N':>6}  {'MPE [m]':>8}  {'MOE [%]':>8}  {'MPE non-anchor':>14}  {'seconds':>7}")
    for r in rows:
        line = (f"{r['n_steps']:>6}  {r['mpe']:>8.4f}  {r['moe']:>8.2f}  "
                f"{r['mpe_nonanchor']:>14.4f}  {r['seconds']:>7.2f}")
        if r.get("error"):
            line += f"  failed: {r['error']}"
        print(line)


def _cmd_run(args: argparse.Namespace) -> int:
    from lfmdr_gym.experiments.env_settings import parse_env_kwargs
    from lfmdr_gym.experiments.mapping import run_episode
    from lfmdr_gym.experiments.params import method_label

    if args.online:
        return _cmd_run_online(args)
    rows = run_episode(args.env, args.steps, args.method, seed=args.seed, every=args.every,
                       params=args.param, out=args.out, policy=args.policy,
                       env_kwargs=parse_env_kwargs(args.env_kwargs))
    print(f"{args.env}, seed {args.seed}, {method_label(rows[-1]['method'], rows[-1]['param'])}")
    _print_scores(rows)
    print_warnings(rows[-1]["warnings"])
    print(f"wrote {args.out}/history.npz, scores.csv, map.csv, map.png")
    return 0


def _cmd_run_online(args: argparse.Namespace) -> int:
    from lfmdr_gym.experiments.env_settings import parse_env_kwargs
    from lfmdr_gym.experiments.live import run_online
    from lfmdr_gym.experiments.params import method_label

    run = run_online(args.env, args.steps, args.method, out=args.out, seed=args.seed,
                     every=args.every, params=args.param, policy=args.policy,
                     env_kwargs=parse_env_kwargs(args.env_kwargs))
    print(f"{args.env}, seed {args.seed}, policy {args.policy}, online "
          f"{method_label(run.method, run.params)}")
    print(f"{'steps':>6s} {'MPE non-anchor [m]':>19s} {'mapped':>7s}")
    unmapped = [r for r in run.checkpoints if r["note"]]
    for r in run.checkpoints:
        mpe = f"{r['mpe']:19.4f}" if not r["note"] else f"{'-':>19s}"
        print(f"{r['n_steps']:6d} {mpe} {r['mapped']:7d}" + ("  no map yet" if r["note"] else ""))
    if unmapped:  # why: what the mapper said at the last of them
        print(f"no map at {unmapped[-1]['n_steps']} steps: {unmapped[-1]['note']}")
    if not run.rows[-1]["note"]:  # (else the final map's warnings are that reason)
        print_warnings(run.map.warnings)
    print("wrote " + ", ".join(str(p) for p in run.written))
    return 0


def _cmd_collect(args: argparse.Namespace) -> int:
    from lfmdr_gym.experiments.env_settings import parse_env_kwargs
    from lfmdr_gym.experiments.episodes import collect_history, describe_history

    history = collect_history(args.env, args.steps, args.seed, out=args.out,
                              env_kwargs=parse_env_kwargs(args.env_kwargs), policy=args.policy)
    print(describe_history(history))
    print(f"wrote {args.out}")
    return 0


def _cmd_mrclam(args: argparse.Namespace) -> int:
    import warnings

    import numpy as np

    from lfmdr_gym.datasets.mrclam import MRCLAMDataWarning
    from lfmdr_gym.experiments.mrclam import map_mrclam_run
    from lfmdr_gym.experiments.params import method_label, parse_params

    kwargs: dict[str, Any] = {"out": args.out, "bin_width": args.bin_width,
                              "groundtruth_fixes": args.groundtruth_fixes,
                              "zero_fill": args.zero_fill}
    if args.robots is not None:
        kwargs["robots"] = args.robots
    if args.anchors is not None:
        kwargs["anchors"] = args.anchors
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", MRCLAMDataWarning)  # they come back in result.warnings
        result = map_mrclam_run(args.run_dir, args.sensor, method=args.method, **kwargs,
                                **parse_params(args.param))
    params = ", ".join(f"{k}={v}" for k, v in result.params.items())
    print(f"{result.run} ({result.sensor}), {method_label(result.method, params)}, anchors "
          f"{list(result.anchor_subjects)}")
    print_warnings(result.warnings)
    non_anchor = ~np.isin(result.subjects, result.anchor_subjects)
    mapped = int(np.sum(non_anchor & np.isfinite(result.positions).all(axis=1)))
    which = ("the" if mapped == int(non_anchor.sum())
             else f"the {mapped} mapped (of {int(non_anchor.sum())})")
    print(f"MPE {result.mpe:.3f} m, MOE {result.moe:.2f} % over {which} non-anchor landmarks "
          f"(anchors' centroid baseline: MPE {result.centroid_mpe:.3f} m)")
    written = [str(p) for p in (result.csv_path, result.png_path) if p is not None]
    if written:
        print("wrote " + " and ".join(written))
    return 0


def _cmd_compare(args: argparse.Namespace) -> int:
    from lfmdr_gym.experiments.reproducibility import compare_tables

    problems = compare_tables(args.fresh, args.reference, {
        "mpe_abs": args.mpe_abs, "mpe_rel": args.mpe_rel, "moe_abs": args.moe_abs,
        "moe_rel": args.moe_rel})
    if problems:
        print(f"{args.fresh} does not reproduce {args.reference}:")
        for line in problems:
            print(f"  {line}")
        return 1
    print(f"{args.fresh} reproduces {args.reference} (MPE within {args.mpe_abs} m or "
          f"{args.mpe_rel:.0%}, MOE within {args.moe_abs} points or {args.moe_rel:.0%})")
    return 0


# --------------------------------------------------------------------------- entry point
def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``lfmdr`` console script; returns the exit status."""
    parser = build_parser()
    args = parser.parse_args(argv)
    previous = signal.getsignal(signal.SIGTERM)
    if previous is signal.SIG_DFL:
        # A polite kill (SIGTERM) stops like Ctrl-C: finished work is kept and summarised.
        signal.signal(signal.SIGTERM, _terminate)
    try:
        return int(args.handler(args))
    except (ValueError, FileNotFoundError, NotADirectoryError, PermissionError) as exc:
        # Bad input is reported in one line, like argparse's own errors, without a traceback.
        print(f"lfmdr {args.command}: error: {exc}", file=sys.stderr)
        return EXIT_USAGE
    except KeyboardInterrupt:
        print("\ninterrupted", file=sys.stderr)
        return EXIT_INTERRUPTED
    except BrokenPipeError:
        # Output piped into a command that stopped reading (`lfmdr ... | head`): not an error
        # worth a traceback. Point stdout at devnull so the interpreter's final flush is quiet.
        import os

        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 0
    finally:
        if previous is signal.SIG_DFL:
            signal.signal(signal.SIGTERM, previous)


def _terminate(signum: int, frame: Any) -> None:
    """SIGTERM stops like Ctrl-C: by whatever handles SIGINT now (a protocol's run remembers
    the interrupt, so that one landing in a finaliser still stops it), else as an interrupt."""
    handler = signal.getsignal(signal.SIGINT)
    if callable(handler):
        handler(signum, frame)
    raise KeyboardInterrupt(f"signal {signum}")


if __name__ == "__main__":
    sys.exit(main())
