"""Where tasks run: in this process, in local worker processes (joblib's loky backend), or on a
Dask cluster (joblib's dask backend) — the same calls on every engine.

The main process hands out tasks and is the only one that writes results. Ctrl-C (SIGINT) is
its to handle: local workers ignore it, so a task is never cut short into a false failure, and
on an interrupt the main process terminates its workers at once instead of waiting for them.
"""

from __future__ import annotations

import signal
import sys
import threading
import warnings
from collections.abc import Callable, Iterable, Iterator
from contextlib import contextmanager
from typing import Any

import numpy as np

__all__ = ["ENGINES", "check_jobs", "engine_name", "parallel", "worker_context"]

ENGINES = ("serial", "loky", "dask")
_PREPARED = False


def check_jobs(jobs: int) -> int:
    if isinstance(jobs, bool) or not isinstance(jobs, int | np.integer) or jobs == 0 or jobs < -1:
        raise ValueError(f"jobs must be a positive integer or -1 (all cores), got {jobs!r}")
    return int(jobs)


def engine_name(jobs: int, scheduler: str | None) -> str:
    """``"dask"`` with a scheduler address, ``"loky"`` with several jobs, else ``"serial"``."""
    return "dask" if scheduler else ("serial" if jobs == 1 else "loky")


@contextmanager
def worker_context(engine: str) -> Iterator[None]:
    """Around every task on a worker: one BLAS/OpenMP thread (N workers use N cores, not
    N x N), no nested joblib parallelism (scikit-learn would split its work differently and
    round differently: the same map must come out on every engine), and, in a local worker
    process, SIGINT ignored (Ctrl-C reaches the whole process group; only the main process acts
    on it, so no task is cut short into a false failure)."""
    global _PREPARED
    if engine == "serial":
        yield
        return
    if not _PREPARED:
        from threadpoolctl import threadpool_limits

        threadpool_limits(1)
        if engine == "loky" and threading.current_thread() is threading.main_thread():
            signal.signal(signal.SIGINT, signal.SIG_IGN)
        _PREPARED = True
    from joblib import parallel_config

    with parallel_config(backend="sequential"):
        yield


def _stop_local_workers() -> None:
    """Terminate loky's worker processes now (an interrupted run must not wait for them)."""
    from joblib.externals.loky import get_reusable_executor

    get_reusable_executor().shutdown(wait=False, kill_workers=True)


@contextmanager
def parallel(
    jobs: int, scheduler: str | None, timeout: float = 10.0
) -> Iterator[Callable[[Iterable[Any]], Iterator[Any]]]:
    """A function running delayed calls and yielding results as they finish, on the chosen
    engine: in this process (jobs=1), loky processes, or a Dask cluster via joblib's backend."""
    from joblib import Parallel, parallel_config

    engine = engine_name(jobs, scheduler)
    if engine == "dask":
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
    if engine == "serial":
        yield lambda calls: (fn(*args, **kwargs) for fn, args, kwargs in calls)
        return
    with parallel_config(backend="loky", n_jobs=jobs, inner_max_num_threads=1), \
            warnings.catch_warnings(), _remembered_interrupt() as interrupted:
        # On Ctrl-C joblib warns that running tasks were cancelled: expected, they are redone.
        warnings.filterwarnings("ignore", message=".*still being processed by the workers")

        def run(calls: Iterable[Any]) -> Iterator[Any]:
            for result in Parallel(return_as="generator_unordered", batch_size=1)(calls):
                yield result
                interrupted.raise_if_set()

        try:
            yield run
            interrupted.raise_if_set()
        except KeyboardInterrupt:
            _stop_local_workers()
            raise


class _Interrupt:
    """Whether SIGINT arrived: set by the handler, which also raises KeyboardInterrupt."""

    def __init__(self) -> None:
        self.event = threading.Event()

    def handler(self, signum: int, frame: Any) -> None:
        self.event.set()
        raise KeyboardInterrupt

    def raise_if_set(self) -> None:
        if self.event.is_set():
            raise KeyboardInterrupt


@contextmanager
def _remembered_interrupt() -> Iterator[_Interrupt]:
    """Remember a Ctrl-C as well as raising it. The KeyboardInterrupt a signal raises can land
    inside a library's cleanup code (a finaliser, a callback) that swallows it; the remembered
    flag stops the run at the next result all the same, and Python's report of the swallowed
    interrupt ("Exception ignored in ...", a traceback on stderr) is left out."""
    interrupt = _Interrupt()
    if threading.current_thread() is not threading.main_thread():
        yield interrupt
        return
    previous = signal.signal(signal.SIGINT, interrupt.handler)
    previous_hook = sys.unraisablehook

    def quiet_remembered_interrupt(unraisable: Any) -> None:
        # the interrupt a finaliser swallowed is remembered: not reported as an error
        if not (isinstance(unraisable.exc_value, KeyboardInterrupt) and interrupt.event.is_set()):
            previous_hook(unraisable)

    sys.unraisablehook = quiet_remembered_interrupt
    try:
        yield interrupt
    finally:
        signal.signal(signal.SIGINT, previous)
        sys.unraisablehook = previous_hook
