"""Observation histories: the per-object matrix a mapper takes, plus the ground truth that scores it.

A :class:`History` is what one episode (or one logged run) leaves behind. Its ``matrix`` has one
row per object and, per step, ``columns_per_step`` columns (:data:`mappers.sensors.COLUMNS_PER_STEP`:
1 for visibility (0/1) and range, 2 for bearing (cos, sin)). Columns are in step order, so the
first ``n`` steps of a history are its first ``n * columns_per_step`` columns (:meth:`History.head`).

Ground truth (object positions, robot poses) travels with the history for scoring only; a mapper
is given the matrix and the anchors, nothing else.
"""

from __future__ import annotations

import json
import os
import zipfile
import zlib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from lfmdr_gym import compact
from lfmdr_gym.atomic import atomic_write
from mappers.align import check_anchor_ids
from mappers.sensors import COLUMNS_PER_STEP, check_sensor, check_timeline

FORMAT = "lfmdr-history"
FORMAT_VERSION = 2
SPARSE_MASK_VERSION = 3
READABLE_VERSIONS = (1, 2, 3)  # 1: dense float64 matrix only; 2: also the compact (sparse) form;
# 3: also a sparse mask (mask_indices, mask_indptr, mask_shape)
_ZIP_MAGIC = b"PK\x03\x04"  # an .npz is a zip archive


class HistoryFileError(ValueError):
    """A file that is not a readable lfmdr history (damaged, foreign, or of another version)."""


@dataclass(frozen=True, eq=False)
class History:
    """Per-object observation histories of one episode, with the ground truth to score a map.

    Attributes:
        sensor: ``"visibility"``, ``"bearing"`` or ``"range"``.
        matrix: (M, N * columns_per_step) float64, one row per object. May be given in a
            compact form (a ``scipy.sparse`` matrix, or float32), which is kept as given
            (:attr:`compact`); reading ``matrix`` then builds the float64 matrix if it fits in
            :data:`lfmdr_gym.compact.MAX_DENSE_BYTES` (else DenseTooLargeError naming
            :attr:`sparse`, the accessor that always works).
        object_positions: (M, 2) true object positions [m] (NaN where unknown).
        anchor_ids: (A,) indices of the anchor objects, A >= 3.
        anchor_positions: (A, 2) known positions of the anchors [m].
        robot_poses: (N, 3) true robot pose (x, y, heading) after each step, or None for
            logged data without it. Never given to a mapper.
        mask: None when every entry was observed, else a (M, N * columns_per_step) bool array,
            True where the entry was observed (an env with imperfect sensing always gives one:
            its ``"observed"`` flags, repeated over a step's columns). May be given as a scipy
            sparse bool matrix (a compact masked history), which is kept as given; reading
            ``mask`` then builds the dense array within the memory budget
            (:attr:`sparse_mask` always works).
        meta: JSON-serialisable facts about where the history came from (env id, seed, ...).
        timeline: None (one robot, one step per tick) or (N, 2) int64: the robot that took each
            step and the tick of its clock (logged data binned in time, several robots).
    """

    sensor: str
    matrix: np.ndarray
    object_positions: np.ndarray
    anchor_ids: np.ndarray
    anchor_positions: np.ndarray
    robot_poses: np.ndarray | None = None
    mask: np.ndarray | None = None
    meta: dict[str, Any] = field(default_factory=dict)
    timeline: np.ndarray | None = None

    def __post_init__(self) -> None:
        check_sensor(self.sensor)
        columns = COLUMNS_PER_STEP[self.sensor]
        matrix = compact.check_compact(self.__dict__["_data"])
        if matrix.ndim != 2:
            raise ValueError(f"matrix must be 2-D (objects x columns), got shape {matrix.shape}")
        m, d = matrix.shape
        if d % columns:
            raise ValueError(
                f"matrix has {d} columns, not a multiple of {columns} "
                f"(columns per step for {self.sensor!r})"
            )
        obj = np.asarray(self.object_positions, dtype=np.float64)
        if obj.shape != (m, 2):
            raise ValueError(f"object_positions must have shape ({m}, 2), got {obj.shape}")
        ids = check_anchor_ids(self.anchor_ids, m, min_count=0)
        apos = np.asarray(self.anchor_positions, dtype=np.float64)
        if apos.shape != (ids.size, 2):
            raise ValueError(f"anchor_positions must have shape ({ids.size}, 2), got {apos.shape}")
        poses = None
        if self.robot_poses is not None:
            poses = np.asarray(self.robot_poses, dtype=np.float64)
            if poses.ndim != 2 or poses.shape[1] != 3:
                raise ValueError(f"robot_poses must have shape (N, 3), got {poses.shape}")
            if poses.shape[0] != d // columns:
                raise ValueError(f"robot_poses has {poses.shape[0]} rows for {d // columns} steps")
        mask = self.__dict__["_mask"]
        if mask is not None:
            mask = compact.check_mask(mask, matrix.shape)
        object.__setattr__(self, "matrix", matrix)
        self.__dict__.pop("_dense", None)
        object.__setattr__(self, "object_positions", obj)
        object.__setattr__(self, "anchor_ids", ids)
        object.__setattr__(self, "anchor_positions", apos)
        object.__setattr__(self, "robot_poses", poses)
        object.__setattr__(self, "mask", mask)
        self.__dict__.pop("_dense_mask", None)
        object.__setattr__(self, "meta", dict(self.meta))
        object.__setattr__(self, "timeline", check_timeline(self.timeline, d // columns))

    # ------------------------------------------------------------------ views
    @property
    def columns_per_step(self) -> int:
        return COLUMNS_PER_STEP[self.sensor]

    @property
    def n_objects(self) -> int:
        return self.shape[0]

    @property
    def n_steps(self) -> int:
        return self.shape[1] // self.columns_per_step

    @property
    def shape(self) -> tuple[int, int]:
        """(M, N * columns_per_step), without building the dense matrix."""
        return tuple(self.__dict__["_data"].shape)

    @property
    def compact(self) -> bool:
        """Whether the matrix is stored compactly (sparse, or float32) rather than as float64."""
        data = self.__dict__["_data"]
        return compact.is_sparse(data) or data.dtype != np.float64

    @property
    def is_sparse(self) -> bool:
        """Whether the matrix is stored as a scipy sparse matrix (visibility, limited range)."""
        return compact.is_sparse(self.__dict__["_data"])

    @property
    def sparse(self):
        """The matrix as a float64 ``scipy.sparse.csr_array`` (zeros not stored): works at any size."""
        return compact.to_sparse(self.__dict__["_data"])

    @property
    def masked(self) -> bool:
        """Whether the history has a mask (without building a dense one)."""
        return self.__dict__["_mask"] is not None

    @property
    def sparse_mask(self):
        """The mask as a bool ``scipy.sparse.csr_array`` (None without one): works at any size."""
        mask = self.__dict__["_mask"]
        return None if mask is None else compact.to_sparse_mask(mask)

    def dense(self, max_bytes: int | None = None) -> np.ndarray:
        """The (M, D) float64 matrix; for a compact history built once (cached) if it needs at most
        ``max_bytes`` (default :data:`lfmdr_gym.compact.MAX_DENSE_BYTES`), else DenseTooLargeError."""
        data = self.__dict__["_data"]
        if "_dense" not in self.__dict__:
            out = compact.to_dense(data, max_bytes)
            if out is data:
                return out
            self.__dict__["_dense"] = out
        return self.__dict__["_dense"]

    def head(self, n_steps: int) -> History:
        """The history of the first ``n_steps`` steps (a checkpoint of the same episode)."""
        if not 0 < n_steps <= self.n_steps:
            raise ValueError(f"n_steps must be in [1, {self.n_steps}], got {n_steps}")
        cols = n_steps * self.columns_per_step
        return History(
            sensor=self.sensor,
            matrix=self.__dict__["_data"][:, :cols],
            object_positions=self.object_positions,
            anchor_ids=self.anchor_ids,
            anchor_positions=self.anchor_positions,
            robot_poses=None if self.robot_poses is None else self.robot_poses[:n_steps],
            mask=None if not self.masked else self.__dict__["_mask"][:, :cols],
            meta=self.meta,
            timeline=None if self.timeline is None else self.timeline[:n_steps],
        )

    def __repr__(self) -> str:
        return (
            f"History(sensor={self.sensor!r}, objects={self.n_objects}, steps={self.n_steps}, "
            f"anchors={self.anchor_ids.tolist()}, masked={self.masked})"
        )

    # ------------------------------------------------------------------ files
    def save(self, path: str | os.PathLike) -> Path:
        """Write the history to ``path`` (.npz) atomically: a reader never sees a half-written file."""
        path = Path(path)
        if path.suffix != ".npz":
            raise ValueError(f"history files end in .npz, got {path.name!r}")
        arrays: dict[str, np.ndarray] = {
            "format": np.array(FORMAT),
            # version 1 where it suffices, so that older lfmdr still reads today's dense files
            "format_version": np.array(SPARSE_MASK_VERSION if compact.is_sparse(
                self.__dict__["_mask"]) else FORMAT_VERSION if self.compact else 1),
            "sensor": np.array(self.sensor),
            **compact.compact_fields(self.__dict__["_data"]),
            "object_positions": self.object_positions,
            "anchor_ids": self.anchor_ids,
            "anchor_positions": self.anchor_positions,
            "meta": np.array(json.dumps(self.meta, sort_keys=True)),
        }
        if self.robot_poses is not None:
            arrays["robot_poses"] = self.robot_poses
        if self.masked:
            arrays.update(compact.mask_fields(self.__dict__["_mask"]))
        if self.timeline is not None:
            arrays["timeline"] = self.timeline
        with atomic_write(path, "wb") as fh:
            np.savez_compressed(fh, **arrays)
        return path

    @classmethod
    def load(cls, path: str | os.PathLike) -> History:
        """Read a history written by :meth:`save`; anything else raises :class:`HistoryFileError`."""
        path = Path(path)
        if not path.is_file():
            raise FileNotFoundError(f"no history file at {path}")
        with open(path, "rb") as fh:
            if fh.read(len(_ZIP_MAGIC)) != _ZIP_MAGIC:
                raise HistoryFileError(f"{path} is not an .npz archive, so not an lfmdr history")
        try:
            with np.load(path, allow_pickle=False) as data:
                files = set(data.files)
                if "format" not in files or str(data["format"]) != FORMAT:
                    raise HistoryFileError(f"{path} is not an lfmdr history file (no '{FORMAT}' tag)")
                version = int(data["format_version"])
                if version not in READABLE_VERSIONS:
                    raise HistoryFileError(
                        f"{path} has history format version {version}; this lfmdr reads "
                        f"versions {', '.join(map(str, READABLE_VERSIONS))}"
                    )
                fields = {k: data[k] for k in files}
        except HistoryFileError:
            raise
        except (OSError, ValueError, EOFError, KeyError, zipfile.BadZipFile, zlib.error,
                NotImplementedError) as exc:  # zlib.error / NotImplementedError: damaged members
            raise HistoryFileError(f"{path} is damaged or not an .npz history: {exc}") from exc
        try:
            return cls(
                sensor=str(fields["sensor"]),
                matrix=compact.from_fields(fields),
                object_positions=fields["object_positions"],
                anchor_ids=fields["anchor_ids"],
                anchor_positions=fields["anchor_positions"],
                robot_poses=fields.get("robot_poses"),
                mask=compact.mask_from_fields(fields),
                meta=json.loads(str(fields["meta"])),
                timeline=fields.get("timeline"),
            )
        except KeyError as exc:
            raise HistoryFileError(f"{path} lacks the field {exc.args[0]!r}") from exc
        except ValueError as exc:
            raise HistoryFileError(f"{path} holds an inconsistent history: {exc}") from exc


def _mask_get(self: History) -> np.ndarray | None:
    mask = self.__dict__["_mask"]
    if mask is None or isinstance(mask, np.ndarray):
        return mask
    if "_dense_mask" not in self.__dict__:
        self.__dict__["_dense_mask"] = compact.to_dense_mask(mask)
    return self.__dict__["_dense_mask"]


def _mask_set(self: History, value: Any) -> None:
    self.__dict__["_mask"] = value


def _matrix_get(self: History) -> np.ndarray:
    return self.dense()


def _matrix_set(self: History, value: Any) -> None:
    self.__dict__["_data"] = value


# ``matrix`` is a dataclass field (History(matrix=...) and the frozen __init__ set it) whose value
# is kept as stored; reading it goes through History.dense, so a compact history densifies only
# on demand and refuses a matrix beyond the memory budget.
History.matrix = property(_matrix_get, _matrix_set, doc="The (M, D) float64 matrix (History.dense).")
# ``mask`` likewise: kept as stored (dense or sparse); reading it gives the dense bool array.
History.mask = property(_mask_get, _mask_set, doc="The (M, D) bool mask or None (History.sparse_mask).")


def __getattr__(name: str):
    # collect() and collect_vector() live in lfmdr_gym.recording; older code imports them here
    if name in ("collect", "collect_vector"):
        from lfmdr_gym import recording

        return getattr(recording, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
