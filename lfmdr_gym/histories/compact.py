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


def check_mask(mask: Any, shape: tuple[int, ...]) -> Any:
    """A history's mask as stored: a bool ndarray, or a bool csr_array with sorted indices."""
    if sp.issparse(mask):
        out = sp.csr_array(mask)
        if out.dtype != np.bool_ or out.shape != tuple(shape):
            raise ValueError(f"mask must be a bool matrix of shape {tuple(shape)}, got sparse "
                             f"{out.dtype} {out.shape}")
        out.sum_duplicates()
        out.sort_indices()
        return out
    arr = np.asarray(mask)
    if arr.dtype != np.bool_ or arr.shape != tuple(shape):
        raise ValueError(f"mask must be a bool array of shape {tuple(shape)}, got {arr.dtype} {arr.shape}")
    return arr


def to_dense_mask(mask: Any, max_bytes: int | None = None) -> np.ndarray:
    """The (M, D) bool array of a (sparse) mask; DenseTooLargeError beyond ``max_bytes``."""
    if isinstance(mask, np.ndarray):
        return mask
    budget = MAX_DENSE_BYTES if max_bytes is None else int(max_bytes)
    need = int(np.prod(mask.shape, dtype=np.int64))
    if need > budget:
        raise DenseTooLargeError(
            f"a dense bool mask of shape {mask.shape} needs {need / 2**30:.1f} GiB, above the "
            f"budget of {budget / 2**30:.1f} GiB; use History.sparse_mask"
        )
    return mask.toarray()


def to_sparse_mask(mask: Any) -> sp.csr_array:
    """A mask as a bool ``csr_array`` (False not stored)."""
    out = sp.csr_array(mask if sp.issparse(mask) else np.asarray(mask, dtype=bool), dtype=bool)
    out.eliminate_zeros()
    return out


def mask_fields(mask: Any) -> dict[str, np.ndarray]:
    """The arrays a history file stores for a mask (``mask`` for a dense one; a sparse one as
    its structure, every stored value being True)."""
    if not sp.issparse(mask):
        return {"mask": np.asarray(mask)}
    mask = to_sparse_mask(mask)
    return {"mask_indices": mask.indices, "mask_indptr": mask.indptr,
            "mask_shape": np.array(mask.shape, dtype=np.int64)}


def mask_from_fields(fields: dict[str, np.ndarray]) -> Any:
    """The stored mask from a file's arrays (either form), or None."""
    if any(name in fields for name in _SPARSE_MASK_FIELDS):  # (one missing: a KeyError)
        indices = fields["mask_indices"]
        return sp.csr_array((np.ones(indices.size, bool), indices, fields["mask_indptr"]),
                            shape=_shape(fields["mask_shape"], "mask_shape"))
    return fields.get("mask")


_SPARSE_MASK_FIELDS = ("mask_indices", "mask_indptr", "mask_shape")


def _shape(value: np.ndarray, name: str) -> tuple[int, int]:
    """A stored (rows, columns) shape: two non-negative integers; anything else a ValueError."""
    value = np.asarray(value)
    if value.shape != (2,) or value.dtype.kind not in "iu" or np.any(value < 0):
        raise ValueError(f"{name!r} must be two non-negative integers, got {value!r}")
    return int(value[0]), int(value[1])


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
    shape = _shape(fields["matrix_shape"], "matrix_shape")
    return sp.csr_array(
        (fields["matrix_data"], fields["matrix_indices"], fields["matrix_indptr"]), shape=shape
    )


class CompactSteps:
    """One episode's readings stored compactly as they arrive (``collect(..., compact=True)``).

    Visibility keeps, per step, the ids of the objects seen and their readings; bearing and range
    keep a float32 buffer (range becomes sparse at the end when most readings are 0). Assigned
    step by step (``steps[t] = reading``) like the (N, M, ...) buffer it replaces.

    ``masked=True`` (an env with imperfect sensing): each step is recorded with its ``observed``
    flags (:meth:`record`), and every sensor keeps only the observed objects' ids and readings, so
    :meth:`matrix` and :meth:`mask` are both sparse (a limited range observes a few objects a step).
    """

    def __init__(self, n_steps: int, sample: np.ndarray, sensor: str, masked: bool = False) -> None:
        self.n_steps, self.sensor, self.masked = n_steps, sensor, bool(masked)
        self.shape = sample.shape
        self.dtype = sample.dtype if sample.dtype in (np.int8, np.bool_, np.float32) else np.float64
        if sensor == "visibility" or self.masked:
            self._ids: list[np.ndarray] = []
            self._vals: list[np.ndarray] = []
        else:
            self._buf = np.empty((n_steps, *sample.shape), dtype=np.float32)
        if sensor != "visibility":
            self.dtype = np.float32
        self._count = 0

    def record(self, value: Any, observed: Any) -> None:
        """Store the next step of a masked episode: the reading and its ``observed`` flags (M,)."""
        if not self.masked:
            raise ValueError("record() is for masked episodes; assign steps[t] = reading instead")
        v = np.asarray(value)
        seen = np.asarray(observed)
        if v.shape != self.shape or seen.shape != self.shape[:1]:
            raise ValueError(f"a reading must have shape {self.shape} and its observed flags "
                             f"{self.shape[:1]}, got {v.shape} and {seen.shape}")
        ids = seen.nonzero()[0]
        self._ids.append(ids)
        self._vals.append(v.take(ids, axis=0).astype(self.dtype, copy=False))
        self._count += 1

    def _by_step(self, values: list[np.ndarray]) -> sp.csr_array:
        """The (M, N * columns) csr matrix of per-step (ids, values) lists, columns interleaved."""
        n, m = self._count, self.shape[0]
        c = int(np.prod(self.shape[1:], dtype=int))
        counts = np.fromiter((ids.size for ids in self._ids), dtype=np.int64, count=n)
        ids = np.concatenate(self._ids) if n else np.zeros(0, np.int64)
        data = (np.concatenate([v.reshape(-1, c) for v in values]) if n
                else np.zeros((0, c), self.dtype))
        steps = np.repeat(np.arange(n, dtype=np.int64), counts)
        rows = np.repeat(ids, c)
        cols = (steps[:, None] * c + np.arange(c)).ravel()
        out = sp.coo_array((data.ravel(), (rows, cols)), shape=(m, n * c)).tocsr()
        out.sort_indices()
        return out

    def mask(self) -> sp.csr_array:
        """The (M, N * columns) bool mask of a masked episode: True on each observed object's
        columns of its steps (a sparse form of ``collect``'s dense mask)."""
        if not self.masked:
            raise ValueError("only a masked episode has a mask")
        return self._by_step([np.ones((ids.size, *self.shape[1:]), bool) for ids in self._ids])

    def __len__(self) -> int:
        return self.n_steps

    def __setitem__(self, t: int, value: Any) -> None:
        if self.masked:
            raise ValueError("a masked episode is recorded with record(value, observed)")
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
        if self.masked:  # the observed readings; unobserved entries are 0, as collect zeroes them
            out = self._by_step(self._vals)
            out.eliminate_zeros()
            return out
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
