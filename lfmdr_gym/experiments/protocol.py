"""The paper's protocol (SPEC §5): random-walk episodes x methods x parameters x checkpoints.

A *unit* of work is one (episode, method, parameter, checkpoint): map the first ``n_steps`` of an
episode's history with one method and parameter, and score the map. The protocol asks for every
method over its whole grid at the last checkpoint and for each method's default (the paper's
optimum) at every checkpoint, which gives the tables and the MPE-versus-N curves.

How it stays fast and safe:
- each episode is collected once and cached as ``DIR/histories/L<layout>_P<pose>.npz``;
- units are packed into tasks of bounded cost that share one episode and checkpoint, so a worker
  loads (and caches) a history once per task and big arrays never travel through pickles;
- tasks run with joblib (loky processes, BLAS limited to one thread per worker) or on a Dask
  cluster through joblib's dask backend; results come back to the main process, which alone
  writes them to the :class:`~lfmdr_gym.experiments.store.ResultStore` as they arrive;
- a rerun with the same directory skips every stored unit (resume after Ctrl-C or SIGKILL).

The single-episode workflows behind ``lfmdr run``, ``lfmdr map`` and ``lfmdr collect`` live here
too: they are the protocol's building blocks used one at a time.
"""

from __future__ import annotations

import csv
import dataclasses
import inspect
import itertools
import math
import os
import time
import warnings
from collections import OrderedDict, defaultdict
from collections.abc import Callable, Iterable, Iterator, Mapping, Sequence
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from lfmdr_gym.atomic import atomic_write
from lfmdr_gym.experiments.store import RESULTS, ResultStore, ensure_writable_dir
from lfmdr_gym.history import History, HistoryFileError

MODES: dict[str, str] = {"visibility": "LFMDR-Visibility-v0", "bearing": "LFMDR-Bearing-v0",
                         "range": "LFMDR-Range-v0"}
"""Protocol mode -> the environment id its episodes run in (range: beyond the paper, same protocol)."""

DEFAULT_EVERY: dict[str, int] = {"visibility": 500, "bearing": 200, "range": 200}
"""Default checkpoint interval per sensor (SPEC §5; range follows bearing)."""

HISTORIES = "histories"

# Typical seconds of one map per method at M = 50 on one core (benchmarks/bench_protocol.py;
# SDE solves a semidefinite program). Used only to pack units into tasks of about
# _TASK_BUDGET seconds and to start the slowest tasks first, so none straggles at the end.
_METHOD_COST: dict[str, float] = {"SDE": 0.5, "CAL-SMA": 0.17}
_DEFAULT_COST = 0.03
_TASK_BUDGET = 0.5


def _methods() -> Mapping[str, Any]:
    from mappers import METHODS  # deferred: importing the mappers (cvxpy) costs a second

    return METHODS


def resolve_methods(names: Iterable[str] | None, sensor: str | None = None) -> tuple[str, ...]:
    """Canonical method labels (case-insensitive match); for None, every method of
    ``mappers.METHODS`` that maps ``sensor``'s histories. A named method that does not: ValueError."""
    methods = _methods()

    def fits(label: str) -> bool:
        return sensor is None or methods[label].sensors is None or sensor in methods[label].sensors

    if names is None:
        return tuple(label for label in methods if fits(label))
    by_lower = {label.lower(): label for label in methods}
    out: list[str] = []
    for name in names:
        label = by_lower.get(str(name).strip().lower())
        if label is None:
            raise ValueError(f"unknown method {name!r}; choose from {', '.join(methods)}")
        if not fits(label):
            raise ValueError(f"method {label!r} does not map {sensor} histories "
                             f"(it maps {', '.join(methods[label].sensors)})")
        if label not in out:
            out.append(label)
    if not out:
        raise ValueError("methods must name at least one method")
    return tuple(out)


def param_label(params: Mapping[str, Any]) -> str:
    """The ``param`` column of a parameter set: ``"n_neighbors=5"``, ``"sigma2=0.5"``, or ``"-"``
    for none (names sorted, values as Python prints them, so :func:`parse_params` reads it back)."""
    if not params:
        return "-"
    return ",".join(f"{k}={params[k]}" for k in sorted(params))


def parse_params(items: Iterable[str] | None) -> dict[str, Any]:
    """``["K=5", "sigma2=0.5"]`` (or ``"K=5,sigma2=0.5"`` items) -> ``{"K": 5, "sigma2": 0.5}``;
    values become int, else float, else stay text."""
    out: dict[str, Any] = {}
    for item in items or ():
        for part in str(item).split(","):
            if not part.strip() or part.strip() == "-":
                continue
            name, sep, text = part.partition("=")
            if not sep or not name.strip() or not text.strip():
                raise ValueError(f"parameters are given as NAME=VALUE, got {part!r}")
            text = text.strip()
            value: Any
            try:
                value = int(text)
            except ValueError:
                try:
                    value = float(text)
                except ValueError:
                    value = text
            out[name.strip()] = value
    return out


PARAM_ALIASES: dict[str, str] = {"K": "n_neighbors", "k": "n_neighbors", "d": "degree",
                                 "sigma^2": "sigma2"}
"""The paper's names of parameters (K, d, sigma^2) -> the mappers' keyword names."""


def user_params(method: str, items: Iterable[str] | Mapping[str, Any] | None) -> dict[str, Any]:
    """``method``'s defaults updated by user parameters (``["K=7"]`` or a dict; paper names
    such as K and d are accepted); unknown names raise ValueError naming the accepted ones."""
    given = dict(items) if isinstance(items, Mapping) else parse_params(items)
    given = {PARAM_ALIASES.get(k, k): v for k, v in given.items()}
    spec = _methods()[method]
    accepted = set(spec.parameters)  # register_method ensures it covers grid and defaults
    unknown = sorted(set(given) - accepted)
    if unknown:
        raise ValueError(f"unknown parameter(s) {unknown} for method {method!r}; "
                         f"it accepts {sorted(accepted) or 'none'}")
    return {**default_params(method), **given}


def grid_params(method: str) -> list[dict[str, Any]]:
    """Every parameter set of ``method``'s grid (one empty set when it has no parameter)."""
    grid = dict(_methods()[method].grid)
    names = sorted(grid)
    return [dict(zip(names, values, strict=True)) for values in itertools.product(*(grid[n] for n in names))]


def default_params(method: str) -> dict[str, Any]:
    """``method``'s default for each parameter its grid sweeps: the spec's default (the paper's
    optimum) or else the factory's own keyword default, so the label names a real value."""
    spec = _methods()[method]
    signature = inspect.signature(spec.factory).parameters
    out: dict[str, Any] = {}
    for name in sorted(spec.grid):
        if name in spec.defaults:
            out[name] = spec.defaults[name]
        elif name in signature and signature[name].default not in (inspect.Parameter.empty, None):
            out[name] = signature[name].default
    return out  # a method choosing its own value (default None) runs with no parameter: "-"


def _seed(*parts: int) -> int:
    """A 31-bit seed derived from integers; independent streams for layouts and poses."""
    return int(np.random.SeedSequence([int(p) for p in parts]).generate_state(1)[0] & 0x7FFFFFFF)


@dataclass(frozen=True)
class Episode:
    """One protocol run: a layout (fixed by ``layout_seed``) and a start pose (by ``pose_seed``)."""

    env_id: str
    layout: int
    pose: int
    layout_seed: int
    pose_seed: int
    steps: int

    @property
    def name(self) -> str:
        return f"L{self.layout}_P{self.pose}"


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
        mode: ``"visibility"`` (Table 1) or ``"bearing"`` (Table 2).
        layouts, poses: the runs are every (layout, pose) pair: 5 x 5 in the paper.
        steps: episode length N (2000 in the paper).
        every: checkpoint interval (None: 500 for visibility, 200 for bearing); must divide steps.
        methods: method labels of ``mappers.METHODS`` (None: all of them), case-insensitive.
        seed: base seed; layout ``i`` uses seed ``f(seed, i)`` and its pose ``j`` uses
            ``f(seed, i, j)`` (numpy ``SeedSequence``), so runs never share random streams.
    """

    mode: str = "visibility"
    layouts: int = 5
    poses: int = 5
    steps: int = 2000
    every: int | None = None
    methods: tuple[str, ...] | None = None
    seed: int = 0
    _grids: dict[str, list[dict[str, Any]]] = field(
        default_factory=dict, init=False, repr=False, compare=False
    )

    def __post_init__(self) -> None:
        if self.mode not in MODES:
            raise ValueError(f"mode must be one of {sorted(MODES)}, got {self.mode!r}")
        for name in ("layouts", "poses", "steps"):
            value = getattr(self, name)
            if not isinstance(value, int | np.integer) or value < 1:
                raise ValueError(f"{name} must be a positive integer, got {value!r}")
        every = DEFAULT_EVERY[self.mode] if self.every is None else self.every
        if not isinstance(every, int | np.integer) or every < 1:
            raise ValueError(f"every must be a positive integer, got {every!r}")
        if self.steps % every:
            raise ValueError(
                f"steps ({self.steps}) must be a multiple of every ({every}): the last checkpoint is N"
            )
        if not isinstance(self.seed, int | np.integer):
            raise ValueError(f"seed must be an integer, got {self.seed!r}")
        object.__setattr__(self, "every", int(every))
        object.__setattr__(self, "methods", resolve_methods(self.methods, self.mode))
        self._grids.update({m: grid_params(m) for m in self.methods})

    @property
    def env_id(self) -> str:
        return MODES[self.mode]

    @property
    def checkpoints(self) -> tuple[int, ...]:
        return tuple(range(self.every, self.steps + 1, self.every))

    @property
    def n_runs(self) -> int:
        return self.layouts * self.poses

    def episodes(self) -> list[Episode]:
        return [
            Episode(self.env_id, i, j, _seed(self.seed, i), _seed(self.seed, i, j), self.steps)
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
        return (self.mode, unit.episode.layout, unit.episode.pose, unit.method, unit.param, unit.n_steps)

    def settings(self) -> dict[str, Any]:
        """What ``manifest.json`` records: a run directory is resumed only with equal settings."""
        return {
            "format": "lfmdr-protocol",
            "version": 1,
            "mode": self.mode,
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
                _param_sort(row["param"]), row["n_steps"])


def _param_sort(label: str) -> tuple[Any, ...]:
    """Sort ``"K=10"`` after ``"K=9"``: numbers compared as numbers."""
    out: list[Any] = []
    for name, value in parse_params([label]).items():
        out.append((name, (0, value, "") if isinstance(value, int | float) else (1, 0, str(value))))
    return tuple(out)


# --------------------------------------------------------------------------- episodes
def _make_env(env_id: str, steps: int, env_kwargs: Mapping[str, Any] | None = None) -> Any:
    import gymnasium as gym

    import lfmdr_gym  # noqa: F401 - registers the env ids

    return gym.make(env_id, max_episode_steps=max(int(steps), 1), **dict(env_kwargs or {}))


def collect_episode(episode: Episode) -> History:
    """Collect one protocol episode with the random-walk agent.

    The layout comes from ``layout_seed`` (a reset with that seed draws it), the start pose and the
    agent's random stream from ``pose_seed``; the layout is held fixed through reset options, so
    the five poses of a layout share its objects and anchors.
    """
    from lfmdr_gym.history import collect
    from lfmdr_gym.policies import RandomWalkPolicy

    env = _make_env(episode.env_id, episode.steps)
    try:
        _, info = env.reset(seed=episode.layout_seed)
        layout = {
            "object_positions": np.array(info["object_positions"], dtype=np.float64),
            "anchor_ids": np.array(info["anchor_ids"], dtype=np.int64),
        }
        fixed = _fixed_layout(env, layout)
        policy = RandomWalkPolicy.for_env(env, seed=episode.pose_seed)
        history = collect(fixed, policy, episode.steps, seed=episode.pose_seed)
    finally:
        env.close()
    meta = dict(history.meta)
    meta.update(
        env_id=episode.env_id, layout=episode.layout, pose=episode.pose,
        layout_seed=episode.layout_seed, pose_seed=episode.pose_seed,
    )
    return _with_meta(history, meta)


def _with_meta(history: History, meta: dict[str, Any]) -> History:
    return dataclasses.replace(history, meta=meta)


def _fixed_layout(env: Any, layout: Mapping[str, np.ndarray]) -> Any:
    """``env`` wrapped so that every reset passes the same layout in ``options``."""
    import gymnasium as gym

    class FixedLayout(gym.Wrapper):
        def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
            return self.env.reset(seed=seed, options={**layout, **(options or {})})

    return FixedLayout(env)


# --------------------------------------------------------------------------- one map, scored
def score_map(positions: np.ndarray, unmapped: Sequence[int], history: History) -> dict[str, float]:
    """MPE (mapped objects), MOE and MPE over mapped non-anchor objects of a map of ``history``."""
    from mappers import mean_orientation_error, mean_position_error

    truth = history.object_positions
    unmapped = [int(i) for i in unmapped]
    non_anchor = sorted(set(unmapped) | {int(i) for i in history.anchor_ids})
    nan = float("nan")
    mapped = history.n_objects - len(unmapped)
    return {
        "mpe": mean_position_error(positions, truth, exclude=unmapped) if mapped else nan,
        "moe": mean_orientation_error(positions, truth, exclude=unmapped) if mapped >= 3 else nan,
        "mpe_nonanchor": (
            mean_position_error(positions, truth, exclude=non_anchor)
            if history.n_objects > len(non_anchor) else nan
        ),
        "unmapped": len(unmapped),
    }


def map_history(history: History, method: str, params: Mapping[str, Any] | None = None) -> Any:
    """Build ``method``'s map of ``history`` (a ``mappers.Map``) from the history and its anchors."""
    from mappers import build_map

    return build_map(
        history.matrix, history.anchor_ids, history.anchor_positions, method,
        sensor=history.sensor, mask=history.mask, **dict(params or {}),
    )


def evaluate(history: History, method: str, params: Mapping[str, Any] | None = None) -> dict[str, Any]:
    """Map and score one unit; a mapper failure becomes NaN scores and an ``error`` message."""
    t0 = time.perf_counter()
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # sklearn/cvxpy chatter would break the progress bar
            result = map_history(history, method, params)
        scores = score_map(result.positions, result.unmapped, history)
        error = ""
    except (ValueError, ArithmeticError) as exc:
        # A method that fails on some data (the paper's HLLE "often failed to run"; the mappers
        # raise MappingError, a ValueError) is a deterministic result to record, not a reason to
        # stop the protocol. Anything else (a bug, MemoryError) stops the run unrecorded, so a
        # rerun retries it.
        nan = float("nan")
        scores = {"mpe": nan, "moe": nan, "mpe_nonanchor": nan, "unmapped": 0}
        error = f"{type(exc).__name__}: {exc}"[:300]
        result = None
    return {**scores, "seconds": time.perf_counter() - t0, "error": error, "map": result}


# --------------------------------------------------------------------------- tasks (workers)
@dataclass(frozen=True)
class _Task:
    episode: Episode
    path: str
    n_steps: int
    units: tuple[tuple[str, str, tuple[tuple[str, Any], ...]], ...]  # (method, param, params)
    mode: str
    cost: float
    # The MethodSpecs of the task's methods. The registry is per process: a method registered in
    # the user's script (register_method) does not exist in a fresh worker process until the
    # task brings it (loky and Dask pickle a script's functions by value).
    specs: tuple[Any, ...] = ()


_HISTORY_CACHE: OrderedDict[str, History] = OrderedDict()
_CACHE_BYTES = 256 * 2**20
_THREADS_LIMITED = False


def _limit_threads() -> None:
    """One BLAS/OpenMP thread per worker process, so N workers use N cores, not N x N."""
    global _THREADS_LIMITED
    if not _THREADS_LIMITED:
        from threadpoolctl import threadpool_limits

        threadpool_limits(1)
        _THREADS_LIMITED = True


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


def _run_task(task: _Task, limit_threads: bool) -> list[dict[str, Any]]:
    if limit_threads:
        _limit_threads()
    _register_specs(task.specs)
    head = _episode_history(task.episode, task.path).head(task.n_steps)
    rows = []
    for method, param, params in task.units:
        result = evaluate(head, method, dict(params))
        result.pop("map")
        rows.append({
            "mode": task.mode, "layout": task.episode.layout, "pose": task.episode.pose,
            "method": method, "param": param, "n_steps": task.n_steps, **result,
        })
    return rows


def _collect_task(episode: Episode, limit_threads: bool) -> History:
    if limit_threads:
        _limit_threads()
    return collect_episode(episode)


def _make_tasks(units: Sequence[Unit], paths: Mapping[Episode, str], mode: str) -> list[_Task]:
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
                tasks.append(_task(ep, paths[ep], n, batch, mode, cost))
                batch, cost = [], 0.0
            batch.append(u)
            cost += c
        if batch:
            tasks.append(_task(ep, paths[ep], n, batch, mode, cost))
    tasks.sort(key=lambda t: -t.cost)
    return tasks


def _task(ep: Episode, path: str, n: int, units: list[Unit], mode: str, cost: float) -> _Task:
    methods = _methods()
    specs = tuple(methods[m] for m in dict.fromkeys(u.method for u in units))
    return _Task(ep, path, n, tuple((u.method, u.param, u.params) for u in units), mode, cost, specs)


@contextmanager
def _parallel(
    jobs: int, scheduler: str | None, timeout: float = 10.0
) -> Iterator[Callable[[Iterable[Any]], Iterator[Any]]]:
    """A function running delayed calls and yielding results as they finish, on the chosen
    engine: in this process (jobs=1), loky processes, or a Dask cluster via joblib's backend."""
    from joblib import Parallel, parallel_config

    if scheduler:
        try:
            from distributed import Client
        except ImportError as exc:  # pragma: no cover - optional extra
            raise ValueError("--scheduler needs dask distributed: pip install 'lfmdr[dask]'") from exc
        try:
            client = Client(scheduler, timeout=timeout)
        except (OSError, TimeoutError, ValueError) as exc:
            raise ValueError(f"cannot reach the Dask scheduler at {scheduler!r}: {exc}") from exc
        try:
            with parallel_config(backend="dask"):
                yield lambda calls: Parallel(return_as="generator_unordered")(calls)
        finally:
            client.close()
        return
    if jobs == 1:
        yield lambda calls: (fn(*args, **kwargs) for fn, args, kwargs in calls)
        return
    with parallel_config(backend="loky", n_jobs=jobs, inner_max_num_threads=1), \
            warnings.catch_warnings():
        # On Ctrl-C joblib warns that running tasks were cancelled: expected, they are redone.
        warnings.filterwarnings("ignore", message=".*still being processed by the workers")
        yield lambda calls: Parallel(return_as="generator_unordered", batch_size=1)(calls)


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


def _check_jobs(jobs: int) -> int:
    if not isinstance(jobs, int | np.integer) or jobs == 0 or jobs < -1:
        raise ValueError(f"jobs must be a positive integer or -1 (all cores), got {jobs!r}")
    return int(jobs)


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
    computes only what is missing. ``jobs`` worker processes (-1: all cores) or a Dask
    ``scheduler`` address run the tasks; the main process is the only writer.
    """
    from joblib import delayed
    from tqdm.auto import tqdm

    jobs = _check_jobs(jobs)
    t0 = time.perf_counter()
    out = ensure_writable_dir(out)
    limit = jobs != 1 or bool(scheduler)
    with ResultStore(out, config.settings(), sort_key=config.sort_key) as store:
        units = config.units()
        todo = [u for u in units if config.key(u) not in store.done]
        resumed = len(units) - len(todo)
        hist_dir = out / HISTORIES
        hist_dir.mkdir(exist_ok=True)
        paths = {ep: str(hist_dir / f"{ep.name}.npz") for ep in config.episodes()}
        needed = {u.episode for u in todo}
        if report:
            needed.add(config.episodes()[0])  # the example maps are drawn from the first run
        missing = [ep for ep in config.episodes() if ep in needed and not _readable(paths[ep])]
        computed = 0
        bars = {"disable": not progress or None, "dynamic_ncols": True}
        try:
            with _parallel(jobs, scheduler, scheduler_timeout) as run:
                with tqdm(total=len(missing), desc=f"{config.mode}: episodes", unit="ep",
                          leave=False, **bars) as bar:
                    for history in run([delayed(_collect_task)(ep, limit) for ep in missing]):
                        history.save(paths[_episode_of(history, missing)])
                        bar.update(1)
                tasks = _make_tasks(todo, paths, config.mode)
                with tqdm(total=len(todo), desc=f"{config.mode}: maps", unit="map",
                          smoothing=0.05, **bars) as bar:
                    for rows in run([delayed(_run_task)(t, limit) for t in tasks]):
                        computed += store.add(rows)  # durable before the next result is awaited
                        bar.update(len(rows))
        finally:
            store.write_results()
        rows = store.rows()
    files: list[Path] = [out / RESULTS]
    if report:
        files += write_report(config, out, rows)
    failed = sum(1 for r in rows if r["error"])
    return ProtocolSummary(out, len(units), computed, resumed, failed,
                           time.perf_counter() - t0, tuple(files))


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


def write_report(config: ProtocolConfig, out: Path, rows: Sequence[Mapping[str, Any]]) -> list[Path]:
    """Table (md + csv), MPE-versus-N curves and example maps of the first run, from the rows."""
    from lfmdr_gym.experiments import figures

    files = figures.write_table(rows, out, mode=config.mode, n_steps=config.steps,
                                defaults={m: param_label(default_params(m)) for m in config.methods},
                                methods=config.methods, n_runs=config.n_runs)
    files.append(figures.plot_curves(rows, out / "mpe_vs_n.png", mode=config.mode,
                                     methods=config.methods,
                                     curve_params={m: param_label(default_params(m))
                                                   for m in config.methods}))
    best = figures.best_params(rows, n_steps=config.steps)
    first = config.episodes()[0]
    history = History.load(out / HISTORIES / f"{first.name}.npz")
    # The paper's example maps (figures 6, 7 / 9), then our best method if it is another one.
    examples = [m for m in figures.PAPER_EXAMPLES.get(config.mode, ()) if m in best]
    ranked = sorted((b["mpe_mean"], m) for m, b in best.items() if math.isfinite(b["mpe_mean"]))
    if ranked and ranked[0][1] not in examples:
        examples.append(ranked[0][1])
    for method in examples:
        label = best[method]["param"]
        result = evaluate(history, method, parse_params([label]))
        if result["map"] is None:
            continue
        path = out / f"map_{figures.slug(method)}.png"
        title = (f"{config.mode}, {method} ({label}), N={config.steps}, run {first.name}: "
                 f"MPE {result['mpe']:.3f} m, MOE {result['moe']:.2f} %")
        files.append(figures.plot_map(result["map"].positions, history, path, title=title))
    return files


# --------------------------------------------------------------------------- one episode
def collect_history(
    env_id: str, steps: int, seed: int | None = 0, out: str | os.PathLike | None = None
) -> History:
    """One random-walk episode of ``env_id`` (layout and pose from ``seed``), saved to ``out``."""
    from lfmdr_gym.history import collect
    from lfmdr_gym.policies import RandomWalkPolicy

    if not isinstance(steps, int | np.integer) or steps < 1:
        raise ValueError(f"steps must be a positive integer, got {steps!r}")
    if out is not None:
        out = Path(out)
        if out.suffix != ".npz":
            raise ValueError(f"the history file must end in .npz, got {out.name!r}")
        ensure_writable_dir(out.parent)
    env = _make_env(env_id, steps)
    try:
        policy = RandomWalkPolicy.for_env(env, seed=seed)
        history = collect(env, policy, int(steps), seed=seed)
    finally:
        env.close()
    history = _with_meta(history, {**history.meta, "env_id": env_id, "seed": seed})
    if out is not None:
        history.save(out)
    return history


def describe_history(history: History) -> str:
    """A few lines summarising a history: size, sensor, how much each object was sensed."""
    lines = [repr(history)]
    if history.sensor == "visibility":
        seen = history.matrix.sum(axis=1)
        lines.append(
            f"sightings per object: min {int(seen.min())}, median {float(np.median(seen)):g}, "
            f"max {int(seen.max())}; never seen: {int((seen == 0).sum())} objects; "
            f"visible per step: {history.matrix.sum(axis=0).mean():.2f} objects on average"
        )
    if history.mask is not None:
        lines.append(f"observed entries: {100 * history.mask.mean():.1f} %")
    if history.robot_poses is not None and history.n_steps > 1:
        moves = np.linalg.norm(np.diff(history.robot_poses[:, :2], axis=0), axis=1)
        blocked = history.meta.get("blocked_moves")
        lines.append(f"robot path: {moves.sum():.1f} m over {history.n_steps} steps "
                     f"(mean move {moves.mean():.3f} m"
                     + (f"; {blocked} moves blocked by an obstacle)" if blocked is not None else ")"))
    meta = {k: v for k, v in history.meta.items() if k in ("env_id", "seed", "layout", "pose")}
    if meta:
        lines.append("from " + ", ".join(f"{k}={v}" for k, v in meta.items()))
    return "\n".join(lines)


def checkpoints_for(steps: int, every: int | None, sensor: str | None) -> tuple[int, ...]:
    """Checkpoints of a single run: multiples of ``every`` up to ``steps`` (which is always one).

    With ``every`` None the sensor's default interval is used and ``steps`` is appended when it
    is not a multiple; an explicit ``every`` must divide ``steps``.
    """
    if not isinstance(steps, int | np.integer) or steps < 1:
        raise ValueError(f"steps must be a positive integer, got {steps!r}")
    if every is None:
        step = min(DEFAULT_EVERY.get(sensor or "", 200), int(steps))
        points = list(range(step, steps + 1, step))
        if points[-1] != steps:
            points.append(int(steps))
        return tuple(points)
    if not isinstance(every, int | np.integer) or every < 1:
        raise ValueError(f"every must be a positive integer, got {every!r}")
    if steps % every:
        raise ValueError(f"steps ({steps}) must be a multiple of every ({every})")
    return tuple(range(every, steps + 1, every))


def run_episode(
    env_id: str,
    steps: int,
    method: str,
    *,
    seed: int | None = 0,
    every: int | None = None,
    params: Iterable[str] | Mapping[str, Any] | None = None,
    out: str | os.PathLike | None = None,
) -> list[dict[str, Any]]:
    """One episode, mapped with ``method`` at every checkpoint; rows of scores per checkpoint.

    With ``out``: writes ``history.npz``, ``scores.csv``, ``map.csv`` and ``map.png`` (the map at
    the last checkpoint) there.
    """
    (method,) = resolve_methods([method], _sensor_of(env_id))
    params = user_params(method, params)
    if out is not None:
        out = ensure_writable_dir(out)
    points = checkpoints_for(steps, every, _sensor_of(env_id))
    history = collect_history(env_id, steps, seed)
    rows, last = [], None
    for n in points:
        result = evaluate(history.head(n), method, params)
        last = result.pop("map")
        rows.append({"n_steps": n, "method": method, "param": param_label(params), **result})
    if out is not None:
        history.save(out / "history.npz")
        _write_csv(out / "scores.csv", rows)
        if last is not None:
            _write_map_csv(out / "map.csv", last.positions, history)
            from lfmdr_gym.experiments import figures

            r = rows[-1]
            figures.plot_map(last.positions, history, out / "map.png",
                             title=f"{env_id}, {method} ({param_label(params)}), N={steps}: "
                                   f"MPE {r['mpe']:.3f} m, MOE {r['moe']:.2f} %")
    return rows


def _sensor_of(env_id: str) -> str | None:
    from lfmdr_gym import ENV_IDS

    return ENV_IDS.get(env_id)


def map_history_file(
    path: str | os.PathLike,
    method: str,
    *,
    params: Iterable[str] | Mapping[str, Any] | None = None,
    n_steps: int | None = None,
    out: str | os.PathLike | None = None,
) -> dict[str, Any]:
    """Map a saved history; scores when its ground truth is known; ``map.csv`` + ``map.png``.

    Returns a dict with ``map`` (the ``mappers.Map``), ``history`` and, when every object's true
    position is in the file, ``mpe``, ``moe``, ``mpe_nonanchor``.
    """
    history = History.load(path)
    (method,) = resolve_methods([method], history.sensor)
    params = user_params(method, params)
    if n_steps is not None:
        history = history.head(n_steps)
    out = ensure_writable_dir(out if out is not None else Path(path).with_suffix(""))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        result = map_history(history, method, params)
    info: dict[str, Any] = {"map": result, "history": history, "method": method,
                            "param": param_label(params), "out": out}
    truth_known = bool(np.all(np.isfinite(history.object_positions)))
    if truth_known:
        info.update(score_map(result.positions, result.unmapped, history))
    _write_map_csv(out / "map.csv", result.positions, history)
    from lfmdr_gym.experiments import figures

    title = f"{Path(path).name}, {method} ({param_label(params)}), N={history.n_steps}"
    if truth_known:
        title += f": MPE {info['mpe']:.3f} m, MOE {info['moe']:.2f} %"
    info["figure"] = figures.plot_map(result.positions, history, out / "map.png", title=title)
    return info


def _write_csv(path: Path, rows: Sequence[Mapping[str, Any]]) -> None:
    with atomic_write(path) as fh:
        writer = csv.DictWriter(fh, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)


def _write_map_csv(path: Path, positions: np.ndarray, history: History) -> None:
    anchors = {int(i) for i in history.anchor_ids}
    with atomic_write(path) as fh:
        writer = csv.writer(fh)
        writer.writerow(["object", "x", "y", "true_x", "true_y", "anchor"])
        for j, (est, tru) in enumerate(zip(positions, history.object_positions, strict=True)):
            writer.writerow([j, *(f"{v:.6g}" for v in est), *(f"{v:.6g}" for v in tru), int(j in anchors)])


__all__ = [
    "DEFAULT_EVERY", "MODES", "Episode", "ProtocolConfig", "ProtocolSummary", "Unit",
    "checkpoints_for", "collect_episode", "collect_history", "default_params", "describe_history",
    "evaluate", "grid_params", "map_history", "map_history_file", "param_label", "parse_params",
    "resolve_methods", "run_episode", "run_protocol", "score_map", "user_params", "write_report",
]
