"""Shared pytest set-up: the project root importable even when pytest runs without an install,
and the fixtures several test files use."""

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
