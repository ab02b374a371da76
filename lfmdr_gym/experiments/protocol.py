"""The paper's protocol (paper §4.1): random-walk episodes x methods x parameters x checkpoints.

A *unit* of work is one (episode, method, parameter, checkpoint): map the first ``n_steps`` of an
episode's history with one method and parameter, and score the map. The protocol asks for every
method over its whole grid at the last checkpoint and for each method's default (the paper's
optimum) at every checkpoint, which gives the tables and the MPE-versus-N curves.

How it stays fast and safe:
- each episode is collected once and cached as ``DIR/histories/L<layout>_P<pose>.npz``;
- units are packed into tasks of bounded cost that share one episode and checkpoint, so a worker
  loads (and caches) a history once per task and big arrays never travel through pickles;
- tasks run on one of the engines of :mod:`~lfmdr_gym.experiments.engine`; results come back to
  the main process, which alone writes them to the
  :class:`~lfmdr_gym.experiments.store.ResultStore` as they arrive;
- a rerun with the same directory skips every stored unit (resume after Ctrl-C or SIGKILL) and
  computes again the units whose mapper failed.
"""

from __future__ import annotations

import math
import os
import time
from collections import OrderedDict, defaultdict
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import InitVar, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from lfmdr_gym.checks import check_int
from lfmdr_gym.experiments.engine import check_jobs, engine_name, parallel, worker_context
from lfmdr_gym.experiments.env_settings import check_env_kwargs
from lfmdr_gym.experiments.episodes import Episode, collect_episode, derived_seed
from lfmdr_gym.experiments.params import (
    default_params,
    grid_params,
    param_label,
    param_sort_key,
    parse_params,
    resolve_methods,
)
from lfmdr_gym.experiments.reproducibility import write_environment
from lfmdr_gym.experiments.scoring import evaluate
from lfmdr_gym.experiments.store import RESULTS, ResultStore, ensure_writable_dir
from lfmdr_gym.histories.history import History, HistoryFileError
from mappers.core.sensors import check_sensor

__all__ = ["DEFAULT_EVERY", "ProtocolConfig", "ProtocolSummary", "Unit", "run_protocol",
           "write_report"]

DEFAULT_EVERY: dict[str, int] = {"visibility": 500, "bearing": 200, "range": 200}
"""Default checkpoint interval per sensor (paper §4.3, §4.4; range follows bearing)."""

HISTORIES = "histories"

# Typical seconds of one map per method at M = 50 on one core (benchmarks/bench_protocol.py;
# SDE solves a semidefinite program). Used only to pack units into tasks of about
# _TASK_BUDGET seconds and to start the slowest tasks first, so none straggles at the end.
_METHOD_COST: dict[str, float] = {"SDE": 0.5, "CAL-SMA": 0.17}
_DEFAULT_COST = 0.03
_TASK_BUDGET = 0.5


@dataclass(frozen=True)
class Unit:
    """One unit of work: map ``episode``'s first ``n_steps`` with ``method`` at ``params``."""

    episode: Episode
    method: str
    param: str
    params: tuple[tuple[str, Any], ...]
    n_steps: int


@dataclass(frozen=True)
class ProtocolConfig:
    """Settings of one protocol run (everything that determines its rows).

    Args:
        sensor: ``"visibility"`` (Table 1), ``"bearing"`` (Table 2) or ``"range"``
            (``mode=`` is accepted as its older name).
        layouts, poses: the runs are every (layout, pose) pair: 5 x 5 in the paper.
        steps: episode length N (2000 in the paper).
        every: checkpoint interval (None: 500 for visibility, 200 otherwise); must divide steps.
        methods: method labels of ``mappers.METHODS`` that map the sensor's histories,
            case-insensitive (None: every method made for complete histories of the sensor, or
            with a sensing limit on, every method that maps masked histories).
        seed: base seed; layout ``i`` uses seed ``f(seed, i)`` and its pose ``j`` uses
            ``f(seed, i, j)`` (numpy ``SeedSequence``), so runs never share random streams.
        env_kwargs: env keywords, e.g. ``{"fov_deg": 90, "max_range": 1.5}`` (imperfect
            sensing, :mod:`lfmdr_gym.sim.sensing_limits`); unknown keywords and bad values are refused.
            With a sensing limit on the histories are masked (:attr:`masked`).
    """

    sensor: str = "visibility"
    layouts: int = 5
    poses: int = 5
    steps: int = 2000
    every: int | None = None
    methods: tuple[str, ...] | None = None
    seed: int = 0
    mode: InitVar[str | None] = None
    env_kwargs: Mapping[str, Any] | tuple[tuple[str, Any], ...] | None = None
    masked: bool = field(default=False, init=False)
    _grids: dict[str, list[dict[str, Any]]] = field(
        default_factory=dict, init=False, repr=False, compare=False
    )

    def __post_init__(self, mode: str | None) -> None:
        if mode is not None:
            if self.sensor != "visibility" and self.sensor != mode:
                raise ValueError(f"sensor={self.sensor!r} and mode={mode!r} disagree (mode is "
                                 "the older name of sensor: give one)")
            object.__setattr__(self, "sensor", mode)
        check_sensor(self.sensor)
        for name in ("layouts", "poses", "steps"):
            check_int(name, getattr(self, name), low=1)
        every = check_int("every", DEFAULT_EVERY[self.sensor] if self.every is None else self.every,
                          low=1)
        if self.steps % every:
            raise ValueError(
                f"steps ({self.steps}) must be a multiple of every ({every}): the last checkpoint is N"
            )
        if not isinstance(self.seed, int | np.integer):
            raise ValueError(f"seed must be an integer, got {self.seed!r}")
        object.__setattr__(self, "every", int(every))
        kwargs, masked = check_env_kwargs(self.sensor, dict(self.env_kwargs or ()))
        object.__setattr__(self, "env_kwargs", tuple(sorted(kwargs.items())))
        object.__setattr__(self, "masked", masked)
        object.__setattr__(self, "methods", resolve_methods(self.methods, self.sensor, masked))
        self._grids.update({m: grid_params(m) for m in self.methods})

    @property
    def env_id(self) -> str:
        from lfmdr_gym import env_id_for

        return env_id_for(self.sensor)

    @property
    def checkpoints(self) -> tuple[int, ...]:
        return tuple(range(self.every, self.steps + 1, self.every))

    @property
    def n_runs(self) -> int:
        return self.layouts * self.poses

    def episodes(self) -> list[Episode]:
        return [
            Episode(self.env_id, i, j, derived_seed(self.seed, i), derived_seed(self.seed, i, j),
                    self.steps, self.env_kwargs)
            for i in range(self.layouts)
            for j in range(self.poses)
        ]

    def units(self) -> list[Unit]:
        """Every unit of the protocol: the full grid at N, each default at every checkpoint."""
        out: list[Unit] = []
        last = (self.steps,)
        for ep in self.episodes():
            for method in self.methods:
                default = default_params(method)
                sets = list(self._grids[method])
                if param_label(default) not in {param_label(p) for p in sets}:
                    sets.append(default)  # a default outside the grid still gets its curve
                for params in sets:
                    label = param_label(params)
                    points = self.checkpoints if label == param_label(default) else last
                    items = tuple(sorted(params.items()))
                    out.extend(Unit(ep, method, label, items, n) for n in points)
        return out

    def key(self, unit: Unit) -> tuple[Any, ...]:
        return (self.sensor, unit.episode.layout, unit.episode.pose, unit.method, unit.param,
                unit.n_steps)

    def settings(self) -> dict[str, Any]:
        """What ``manifest.json`` records: a run directory is resumed only with equal settings
        (env keywords only when given, so that earlier run directories still resume)."""
        env = {"env_kwargs": dict(self.env_kwargs)} if self.env_kwargs else {}
        return {
            **env,
            "format": "lfmdr-protocol",
            "version": 1,
            "sensor": self.sensor,
            "env_id": self.env_id,
            "layouts": self.layouts,
            "poses": self.poses,
            "steps": self.steps,
            "every": self.every,
            "seed": self.seed,
            "methods": list(self.methods),
            "grids": {m: [param_label(p) for p in self._grids[m]] for m in self.methods},
            "defaults": {m: param_label(default_params(m)) for m in self.methods},
        }

    def sort_key(self, row: Mapping[str, Any]) -> tuple[Any, ...]:
        """Order of ``results.csv``: runs, then methods in table order, parameters, checkpoints."""
        order = {m: i for i, m in enumerate(self.methods)}
        return (row["layout"], row["pose"], order.get(row["method"], len(order)), row["method"],
                param_sort_key(row["param"]), row["n_steps"])


# --------------------------------------------------------------------------- tasks (workers)
@dataclass(frozen=True)
class _Task:
    episode: Episode
    path: str
    n_steps: int
    units: tuple[tuple[str, str, tuple[tuple[str, Any], ...]], ...]  # (method, param, params)
    sensor: str
    cost: float
    # The MethodSpecs of the task's methods. The registry is per process: a method registered in
    # the user's script (register_method) does not exist in a fresh worker process until the
    # task brings it (loky and Dask pickle a script's functions by value).
    specs: tuple[Any, ...] = ()


_HISTORY_CACHE: OrderedDict[str, History] = OrderedDict()
_CACHE_BYTES = 256 * 2**20


def _episode_history(episode: Episode, path: str) -> History:
    """The episode's history: from this process's cache, the shared file, or (a remote worker
    without the file) collected again; collection is deterministic, so all three agree."""
    if path in _HISTORY_CACHE:
        _HISTORY_CACHE.move_to_end(path)
        return _HISTORY_CACHE[path]
    try:
        history = History.load(path)
    except (FileNotFoundError, HistoryFileError):
        history = collect_episode(episode)
    _HISTORY_CACHE[path] = history
    # Tasks run slowest-first across episodes, so keep many histories (a 50 x 2000 bearing
    # history is 1.6 MB; loading it again costs ~7 ms per task).
    while len(_HISTORY_CACHE) > 1 and sum(h.matrix.nbytes for h in _HISTORY_CACHE.values()) > _CACHE_BYTES:
        _HISTORY_CACHE.popitem(last=False)
    return history


def _register_specs(specs: Iterable[Any]) -> None:
    """Make this process's registry agree with the parent's for the given specs."""
    from mappers import METHODS, register_method

    for spec in specs:
        if METHODS.get(spec.label) != spec:
            register_method(spec, replace=True)


def _run_task(task: _Task, engine: str) -> list[dict[str, Any]]:
    with worker_context(engine):
        _register_specs(task.specs)
        head = _episode_history(task.episode, task.path).head(task.n_steps)
        rows = []
        for method, param, params in task.units:
            result = evaluate(head, method, dict(params))
            result.pop("map")
            rows.append({
                "sensor": task.sensor, "layout": task.episode.layout, "pose": task.episode.pose,
                "method": method, "param": param, "n_steps": task.n_steps, **result,
            })
        return rows


def _collect_task(episode: Episode, engine: str) -> History:
    with worker_context(engine):
        return collect_episode(episode)


def _make_tasks(units: Sequence[Unit], paths: Mapping[Episode, str], sensor: str) -> list[_Task]:
    """Pack units sharing an (episode, checkpoint) into tasks of about ``_TASK_BUDGET`` seconds
    (one history slice per task, few round trips), slowest first (longest-processing-time
    order, so that no long task straggles at the end)."""
    groups: dict[tuple[Episode, int], list[Unit]] = defaultdict(list)
    for u in units:
        groups[(u.episode, u.n_steps)].append(u)
    tasks: list[_Task] = []
    for (ep, n), members in groups.items():
        batch: list[Unit] = []
        cost = 0.0
        for u in members:
            c = _METHOD_COST.get(u.method, _DEFAULT_COST)
            if batch and cost + c > _TASK_BUDGET:
                tasks.append(_task(ep, paths[ep], n, batch, sensor, cost))
                batch, cost = [], 0.0
            batch.append(u)
            cost += c
        if batch:
            tasks.append(_task(ep, paths[ep], n, batch, sensor, cost))
    tasks.sort(key=lambda t: -t.cost)
    return tasks


def _task(ep: Episode, path: str, n: int, units: list[Unit], sensor: str, cost: float) -> _Task:
    from mappers import METHODS

    specs = tuple(METHODS[m] for m in dict.fromkeys(u.method for u in units))
    return _Task(ep, path, n, tuple((u.method, u.param, u.params) for u in units), sensor, cost,
                 specs)


# --------------------------------------------------------------------------- the protocol
@dataclass(frozen=True)
class ProtocolSummary:
    """What a protocol run did: counts, where the files are, and the report it wrote."""

    out: Path
    total_units: int
    computed: int
    resumed: int
    failed: int
    seconds: float
    files: tuple[Path, ...] = ()

    def __str__(self) -> str:
        lines = [
            f"{self.total_units} results in {self.out / RESULTS} "
            f"({self.computed} computed now, {self.resumed} from an earlier run, "
            f"{self.failed} mapper failures) in {self.seconds:.1f} s"
        ]
        lines += [f"  wrote {p}" for p in self.files]
        return "\n".join(lines)


def _readable(path: str) -> bool:
    try:
        History.load(path)
    except (FileNotFoundError, HistoryFileError):
        return False
    return True


def _episode_of(history: History, episodes: Sequence[Episode]) -> Episode:
    for ep in episodes:
        if history.meta.get("layout") == ep.layout and history.meta.get("pose") == ep.pose:
            return ep
    raise RuntimeError(f"collected history {history.meta} matches no requested episode")


def _compute(config: ProtocolConfig, out: Path, store: ResultStore, todo: Sequence[Unit],
             needed: set[Episode], engine: dict[str, Any], progress: bool) -> int:
    """Collect the missing episodes, then map every unit to do; store rows as they arrive."""
    from joblib import delayed
    from tqdm.auto import tqdm

    hist_dir = out / HISTORIES
    hist_dir.mkdir(exist_ok=True)
    paths = {ep: str(hist_dir / f"{ep.name}.npz") for ep in config.episodes()}
    missing = [ep for ep in config.episodes() if ep in needed and not _readable(paths[ep])]
    name = engine_name(engine["jobs"], engine["scheduler"])
    bars = {"disable": not progress or None, "dynamic_ncols": True}
    computed = 0
    with parallel(engine["jobs"], engine["scheduler"], engine["timeout"]) as run:
        with tqdm(total=len(missing), desc=f"{config.sensor}: episodes", unit="ep",
                  leave=False, **bars) as bar:
            for history in run([delayed(_collect_task)(ep, name) for ep in missing]):
                history.save(paths[_episode_of(history, missing)])
                bar.update(1)
        tasks = _make_tasks(todo, paths, config.sensor)
        with tqdm(total=len(todo), desc=f"{config.sensor}: maps", unit="map",
                  smoothing=0.05, **bars) as bar:
            for rows in run([delayed(_run_task)(t, name) for t in tasks]):
                computed += store.add(rows)  # durable before the next result is awaited
                bar.update(len(rows))
    return computed


def run_protocol(
    config: ProtocolConfig,
    out: str | os.PathLike,
    *,
    jobs: int = 1,
    scheduler: str | None = None,
    scheduler_timeout: float = 10.0,
    progress: bool = True,
    report: bool = True,
) -> ProtocolSummary:
    """Run (or resume) the protocol into ``out`` and write its results, table and figures.

    Every finished unit is stored the moment its task returns; rerunning with the same ``out``
    computes only what is missing (and again what failed). ``jobs`` worker processes (-1: all
    cores) or a Dask ``scheduler`` address run the tasks; the main process is the only writer.
    ``out/environment.json`` records the package versions and the machine.
    """
    jobs = check_jobs(jobs)
    t0 = time.perf_counter()
    out = ensure_writable_dir(out)
    engine = {"jobs": jobs, "scheduler": scheduler, "timeout": scheduler_timeout}
    with ResultStore(out, config.settings(), sort_key=config.sort_key) as store:
        units = config.units()
        todo = [u for u in units if config.key(u) not in store.done or config.key(u) in store.failed]
        needed = {u.episode for u in todo}
        if report:
            needed.add(config.episodes()[0])  # the example maps are drawn from the first run
        try:
            computed = _compute(config, out, store, todo, needed, engine, progress)
        finally:
            store.write_results()
        rows = store.rows()
    files: list[Path] = [out / RESULTS, write_environment(out)]
    if report:
        files += write_report(config, out, rows)
    failed = sum(1 for r in rows if r["error"])
    return ProtocolSummary(out, len(units), computed, len(units) - len(todo), failed,
                           time.perf_counter() - t0, tuple(files))


def write_report(config: ProtocolConfig, out: Path, rows: Sequence[Mapping[str, Any]]) -> list[Path]:
    """Table (md + csv), MPE-versus-N curves and example maps of the first run, from the rows."""
    import lfmdr_gym.experiments.figures as figures

    defaults = {m: param_label(default_params(m)) for m in config.methods}
    files = figures.write_table(rows, out, sensor=config.sensor, n_steps=config.steps,
                                defaults=defaults, methods=config.methods, n_runs=config.n_runs)
    files.append(figures.plot_curves(rows, out / "mpe_vs_n.png", sensor=config.sensor,
                                     methods=config.methods, curve_params=defaults))
    best = figures.best_params(rows, n_steps=config.steps)
    first = config.episodes()[0]
    history = History.load(out / HISTORIES / f"{first.name}.npz")
    # The paper's example maps (figures 6, 7 / 9), then our best method if it is another one.
    examples = [m for m in figures.PAPER_EXAMPLES.get(config.sensor, ()) if m in best]
    ranked = sorted((b["mpe_mean"], m) for m, b in best.items() if math.isfinite(b["mpe_mean"]))
    if ranked and ranked[0][1] not in examples:
        examples.append(ranked[0][1])
    for method in examples:
        label = best[method]["param"]
        result = evaluate(history, method, parse_params([label]))
        if result["map"] is None:
            continue
        path = out / f"map_{figures.slug(method)}.png"
        title = (f"{config.sensor}, {method} ({label}), N={config.steps}, run {first.name}: "
                 f"MPE {result['mpe']:.3f} m, MOE {result['moe']:.2f} %")
        files.append(figures.plot_map(result["map"].positions, history, path, title=title))
    return files
