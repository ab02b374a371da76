"""Compact storage of a history matrix: sparse rows for sparse sensors, float32 for dense ones.

A visibility history is almost all zeros (an object is in sight on a few percent of the steps),
and so is a range history with a ``max_range``: they are kept as a ``scipy.sparse.csr_array``
(objects x columns) holding only the readings that are not 0. Bearing (and unlimited range)
readings are dense and kept as float32, the precision the environment senses them in. Either form
turns back into today's float64 matrix on demand (:func:`to_dense`), unless that matrix would
exceed a memory budget; the sparse form is always available (:func:`to_sparse`).

Files store the compact form as plain arrays (``matrix_data``, ``matrix_indices``,
``matrix_indptr``, ``matrix_shape``), readable with ``np.load(allow_pickle=False)``.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import scipy.sparse as sp

__all__ = [
    "COMPACT_ABOVE_BYTES",
    "CompactSteps",
    "MAX_DENSE_BYTES",
    "DenseTooLargeError",
    "compact_fields",
    "from_fields",
    "is_sparse",
    "to_dense",
    "to_sparse",
]

MAX_DENSE_BYTES = 2 * 2**30
"""Largest float64 matrix [bytes] :func:`to_dense` builds from a compact history (2 GiB)."""

COMPACT_ABOVE_BYTES = 64 * 2**20
"""``collect`` records compactly when the float64 matrix would be larger than this (64 MiB)."""


class DenseTooLargeError(MemoryError, ValueError):
    """A dense matrix was asked for that would exceed the memory budget (use the sparse form)."""


def is_sparse(data: Any) -> bool:
    return sp.issparse(data)


def check_compact(data: Any) -> Any:
    """``data`` as stored: a float64/float32 ndarray or a 2-D csr_array with sorted indices."""
    if sp.issparse(data):
        if data.ndim != 2:
            raise ValueError(f"matrix must be 2-D (objects x columns), got shape {data.shape}")
        out = sp.csr_array(data)
        if out.dtype not in (np.float32, np.float64, np.int8, np.bool_):
            out = out.astype(np.float64)
        out.sum_duplicates()
        out.sort_indices()
        return out
    arr = np.asarray(data)
    if arr.dtype == np.float32:
        return arr
    return np.asarray(arr, dtype=np.float64)


def to_dense(data: Any, max_bytes: int | None = None) -> np.ndarray:
    """The (M, D) float64 matrix of ``data``; DenseTooLargeError beyond ``max_bytes``."""
    if isinstance(data, np.ndarray) and data.dtype == np.float64:
        return data
    budget = MAX_DENSE_BYTES if max_bytes is None else int(max_bytes)
    need = 8 * int(np.prod(data.shape, dtype=np.int64))
    if need > budget:
        raise DenseTooLargeError(
            f"a dense float64 history matrix of shape {data.shape} needs {need / 2**30:.1f} GiB, "
            f"above the budget of {budget / 2**30:.1f} GiB; use History.sparse (a "
            "scipy.sparse.csr_array) or History.dense(max_bytes=...) to raise the budget"
        )
    if sp.issparse(data):
        return data.toarray().astype(np.float64, copy=False)
    return data.astype(np.float64)


def to_sparse(data: Any) -> sp.csr_array:
    """``data`` as a float64 ``csr_array`` (zeros not stored)."""
    if sp.issparse(data):
        return sp.csr_array(data, dtype=np.float64)
    return sp.csr_array(np.asarray(data, dtype=np.float64))


def compact_fields(data: Any) -> dict[str, np.ndarray]:
    """The arrays a history file stores for ``data`` (``matrix`` for a dense one)."""
    if not sp.issparse(data):
        return {"matrix": np.asarray(data)}
    return {
        "matrix_data": data.data,
        "matrix_indices": data.indices,
        "matrix_indptr": data.indptr,
        "matrix_shape": np.array(data.shape, dtype=np.int64),
    }


def from_fields(fields: dict[str, np.ndarray]) -> Any:
    """The stored matrix from a file's arrays (either form); KeyError if neither is there."""
    if "matrix" in fields or "matrix_shape" not in fields:
        return fields["matrix"]
    shape = tuple(int(v) for v in fields["matrix_shape"])
    return sp.csr_array(
        (fields["matrix_data"], fields["matrix_indices"], fields["matrix_indptr"]), shape=shape
    )


class CompactSteps:
    """One episode's readings stored compactly as they arrive (``collect(..., compact=True)``).

    Visibility keeps, per step, the ids of the objects seen and their readings; bearing and range
    keep a float32 buffer (range becomes sparse at the end when most readings are 0). Assigned
    step by step (``steps[t] = reading``) like the (N, M, ...) buffer it replaces.
    """

    def __init__(self, n_steps: int, sample: np.ndarray, sensor: str) -> None:
        self.n_steps, self.sensor = n_steps, sensor
        self.shape = sample.shape
        self.dtype = sample.dtype if sample.dtype in (np.int8, np.bool_, np.float32) else np.float64
        if sensor == "visibility":
            self._ids: list[np.ndarray] = []
            self._vals: list[np.ndarray] = []
        else:
            self._buf = np.empty((n_steps, *sample.shape), dtype=np.float32)
        self._count = 0

    def __len__(self) -> int:
        return self.n_steps

    def __setitem__(self, t: int, value: Any) -> None:
        if t != self._count:
            raise IndexError(f"steps are recorded in order: expected step {self._count}, got {t}")
        v = np.asarray(value)
        if v.shape != self.shape:
            raise ValueError(f"a reading must have shape {self.shape}, got {v.shape}")
        if self.sensor == "visibility":
            ids = v.nonzero()[0]
            self._ids.append(ids)
            self._vals.append(v.take(ids).astype(self.dtype, copy=False))
        else:
            self._buf[t] = v
        self._count += 1

    def matrix(self, sensor: str) -> Any:
        """The recorded steps as the compact (M, N * columns) matrix a History stores."""
        n, m = self._count, self.shape[0]
        per_step = int(np.prod(self.shape[1:], dtype=int))
        if sensor == "visibility":
            if per_step != 1:
                raise ValueError(f"a visibility observation must give 1 value per object, "
                                 f"got shape {self.shape}")
            indptr = np.zeros(n + 1, dtype=np.int64)
            np.cumsum([ids.size for ids in self._ids], out=indptr[1:])
            indices = np.concatenate(self._ids) if self._ids else np.zeros(0, np.int64)
            data = np.concatenate(self._vals) if self._vals else np.zeros(0, self.dtype)
            by_step = sp.csc_array((data, indices, indptr), shape=(m, n))  # column t = step t
            return sp.csr_array(by_step)
        out = np.ascontiguousarray(np.moveaxis(self._buf[:n], 0, 1).reshape(m, n * per_step))
        if sensor == "range" and 3 * np.count_nonzero(out) < out.size:  # sparse pays off
            return sp.csr_array(out)
        return out
