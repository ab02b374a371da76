"""Shared pytest set-up: the project root importable even when pytest runs without an install,
and the fixtures several test files use, and the tests spread over the machine's cores.

With pytest-xdist installed (the ``test`` extra), a plain ``python -m pytest`` runs as
``-n N --dist loadgroup``: N workers, N the CPUs this process may use (at most
:data:`MAX_WORKERS`; no workers on one CPU); tests marked ``xdist_group(name)`` run on one worker
together (those sharing an expensive module fixture, which each worker would build again). This
is done here rather than in ``addopts`` so that ``pytest -p no:xdist``, an environment without
pytest-xdist, and an explicit ``-n``/``--dist`` keep working: ``-n 0`` runs in one process,
``-n 4`` four workers (still by group), ``-p no:xdist`` without xdist at all.
"""

import os
import sys
from pathlib import Path

import pytest
from threadpoolctl import threadpool_limits

ROOT = str(Path(__file__).resolve().parents[1])
if ROOT not in sys.path:
    sys.path.insert(0, ROOT)


@pytest.fixture
def one_blas_thread():
    """One BLAS thread, as ``build_map`` uses on small problems (fastest there, and the same
    rounding on every machine); a test module takes it with
    ``pytestmark = pytest.mark.usefixtures("one_blas_thread")``."""
    with threadpool_limits(limits=1):
        yield


if os.environ.get("PYTEST_XDIST_WORKER"):
    # One BLAS / OpenMP thread per worker (and the processes its tests start): the workers fill
    # the cores already, and a BLAS thread per core in each worker only contends (measured on
    # 2 cores: test_calibrated, test_masked and test_mappers_smacof took 22 s of CPU instead of
    # 40). Set before numpy is imported; a variable the user set is kept.
    for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
        os.environ.setdefault(_var, "1")
    if "numpy" in sys.modules:  # imported already (by a plugin): limit it at run time
        from threadpoolctl import threadpool_limits

        threadpool_limits(int(os.environ["OPENBLAS_NUM_THREADS"]))


MAX_WORKERS = 8
"""Workers at most by default: each imports numpy, scipy, scikit-learn, numba... (~0.3 GB)."""


def _cores() -> int:
    """The CPUs this process may run on (logical ones: a 2-vCPU CI machine has 2, where
    ``-n auto`` may count 1 physical core)."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # not on Linux
        return os.cpu_count() or 1


@pytest.hookimpl(tryfirst=True)
def pytest_cmdline_main(config: pytest.Config) -> None:
    if not config.pluginmanager.hasplugin("xdist"):
        return  # no xdist, or -p no:xdist
    option = config.option
    if hasattr(config, "workerinput"):  # a worker: group its tests as the controller does
        if config.workerinput.get("lfmdr_dist") == "loadgroup":
            option.loadgroup = True  # (a worker reads --dist from the command line only)
        return
    if option.numprocesses is None and not option.tx and not option.usepdb \
            and not option.collectonly and _cores() > 1:
        option.numprocesses = min(_cores(), MAX_WORKERS)
    if option.numprocesses and option.dist == "no" and not option.distload:
        option.dist = "loadgroup"


@pytest.hookimpl(optionalhook=True)
def pytest_configure_node(node) -> None:
    """(pytest-xdist, on the controller) Tell each worker how the tests are distributed."""
    node.workerinput["lfmdr_dist"] = node.config.option.dist
