"""Observation histories: the per-object matrix a mapper takes, plus the ground truth that scores it.

A :class:`History` is what one episode (or one logged run) leaves behind. Its ``matrix`` has one
row per object and, per step, ``columns_per_step`` columns (:data:`mappers.core.sensors.COLUMNS_PER_STEP`:
1 for visibility (0/1) and range, 2 for bearing (cos, sin)). Columns are in step order, so the
first ``n`` steps of a history are its first ``n * columns_per_step`` columns (:meth:`History.head`).

A history is 2-D or 3-D (:attr:`History.dimension`): object and anchor positions have 2 or 3
columns. A 3-D bearing history holds a unit ray per step, 3 columns ``(x, y, z)`` in the sensor's
frame (:func:`step_columns`); visibility and range keep their one column.

A *fused* history holds several sensors' histories of the same objects over the same steps (a
camera's range and bearing, or visibility and bearing of one walk): its ``sensor`` names the set
(:data:`mappers.core.sensors.FUSED_SENSORS`, e.g. ``"range-bearing"``), its ``matrix`` is a mapping
sensor -> matrix and its ``mask`` (if any) is keyed the same way; :attr:`History.parts` gives each
sensor's history on its own. ``build_map`` maps it with the default of the set.

Ground truth (object positions, robot poses) travels with the history for scoring only; a mapper
is given the matrix and the anchors, nothing else.
"""

from __future__ import annotations

import json
import os
import zipfile
import zlib
from collections.abc import Mapping
from dataclasses import dataclass, field, fields
from pathlib import Path
from types import MappingProxyType
from typing import Any

import numpy as np
import scipy.sparse as sp

import lfmdr_gym.histories.compact as compact
from lfmdr_gym.atomic import atomic_write
from mappers.core.align import check_anchor_ids
from mappers.core.sensors import (
    COLUMNS_PER_STEP,
    FUSED_SENSORS,
    check_timeline,
    sensors_of,
)

FORMAT = "lfmdr-history"
FORMAT_VERSION = 4
# 1: dense float64 matrix only; 2: also the compact (sparse) form; 3: also fused histories (one
# matrix per sensor, its fields named "<sensor>.<field>") and sparse masks (mask_indices,
# mask_indptr, mask_shape); 4: 3-D histories (positions (M, 3), bearing 3 columns per step), the
# same fields. A file is written with the lowest version that holds it, so older lfmdr still
# reads what it can and refuses a 3-D file by its version rather than by a shape error.
READABLE_VERSIONS = (1, 2, 3, 4)
DIMENSIONS = (2, 3)
"""The dimensions a history's positions can have (its map's)."""
_ZIP_MAGIC = b"PK\x03\x04"  # an .npz is a zip archive


def step_columns(sensor: str, dimension: int = 2) -> int:
    """Matrix columns one step of ``sensor`` contributes in a ``dimension``-D history: as
    :data:`mappers.core.sensors.COLUMNS_PER_STEP` in 2-D; in 3-D a bearing is a unit ray, 3
    columns ``(x, y, z)`` in the sensor's frame."""
    if dimension not in DIMENSIONS:
        raise ValueError(f"dimension must be one of {list(DIMENSIONS)}, got {dimension!r}")
    if sensor not in COLUMNS_PER_STEP:
        raise ValueError(f"sensor must be one of {list(COLUMNS_PER_STEP)}, got {sensor!r}")
    return 3 if (sensor == "bearing" and dimension == 3) else COLUMNS_PER_STEP[sensor]


class HistoryFileError(ValueError):
    """A file that is not a readable lfmdr history (damaged, foreign, or of another version)."""


@dataclass(frozen=True, eq=False)
class History:
    """Per-object observation histories of one episode, with the ground truth to score a map.

    Attributes:
        sensor: ``"visibility"``, ``"bearing"`` or ``"range"``; or the name of a fused set of
            them (``"range-bearing"``, ``"visibility-bearing"``: :data:`FUSED_SENSORS`), whose
            ``matrix`` is then a mapping sensor -> matrix (one per sensor of the set, each as
            below, the same objects and steps) and whose ``mask`` is None or a mapping with the
            same keys (a value None: that sensor complete).
        matrix: (M, N * columns_per_step) float64, one row per object (columns_per_step:
            :func:`step_columns` of the sensor and the dimension). May be given in a
            compact form (a ``scipy.sparse`` matrix, or float32), which is kept as given
            (:attr:`compact`); reading ``matrix`` then builds the float64 matrix if it fits in
            :data:`lfmdr_gym.histories.compact.MAX_DENSE_BYTES` (else DenseTooLargeError naming
            :attr:`sparse`, the accessor that always works).
        object_positions: (M, 2) true object positions [m] (NaN where unknown); (M, 3) for a
            3-D history (:attr:`dimension`).
        anchor_ids: (A,) indices of the anchor objects, A >= 3.
        anchor_positions: (A, 2) known positions of the anchors [m]; (A, 3) in 3-D.
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
        if len(sensors_of(self.sensor)) > 1:  # (a name it does not know: a ValueError)
            self._init_fused()
            return
        if isinstance(self.__dict__["_data"], Mapping):
            raise ValueError(f"a mapping sensor -> matrix is a fused history: its sensor must name "
                             f"the set (one of {list(FUSED_SENSORS)}), got {self.sensor!r}")
        obj = np.asarray(self.object_positions, dtype=np.float64)
        if obj.ndim != 2 or obj.shape[1] not in DIMENSIONS:
            raise ValueError(f"object_positions must have shape (M, 2) or, for a 3-D history, "
                             f"(M, 3), got {obj.shape}")
        dimension = obj.shape[1]
        columns = step_columns(self.sensor, dimension)
        matrix = compact.check_compact(self.__dict__["_data"])
        if matrix.ndim != 2:
            raise ValueError(f"matrix must be 2-D (objects x columns), got shape {matrix.shape}")
        m, d = matrix.shape
        if d % columns:
            raise ValueError(
                f"matrix has {d} columns, not a multiple of {columns} "
                f"(columns per step for {self.sensor!r} in {dimension}-D)"
            )
        if obj.shape[0] != m:
            raise ValueError(f"object_positions must have shape ({m}, {dimension}), got {obj.shape}")
        ids = check_anchor_ids(self.anchor_ids, m, min_count=0)
        apos = np.asarray(self.anchor_positions, dtype=np.float64)
        if apos.shape != (ids.size, dimension):
            raise ValueError(f"anchor_positions must have shape ({ids.size}, {dimension}) (the "
                             f"dimension of object_positions), got {apos.shape}")
        poses = None
        if self.robot_poses is not None:
            poses = np.asarray(self.robot_poses, dtype=np.float64)
            if poses.ndim != 2 or poses.shape[1] != 3:
                raise ValueError(f"robot_poses must have shape (N, 3), got {poses.shape}")
            if poses.shape[0] != d // columns:
                raise ValueError(f"robot_poses has {poses.shape[0]} rows for {d // columns} steps")
        mask = self.__dict__["_mask"]
        if isinstance(mask, Mapping):
            raise ValueError(f"a mapping sensor -> mask belongs to a fused history; a "
                             f"{self.sensor} history takes one mask or None")
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

    def _init_fused(self) -> None:
        """Validate a fused history: one single-sensor History per sensor of the set (:attr:`parts`)."""
        names = sensors_of(self.sensor)
        matrices = self.__dict__["_data"]
        if not isinstance(matrices, Mapping):
            raise ValueError(f"a {self.sensor} history needs a mapping sensor -> matrix with the "
                             f"keys {list(names)}, got {type(matrices).__name__}")
        masks = self.__dict__["_mask"]
        if masks is not None and not isinstance(masks, Mapping):
            raise ValueError(f"the mask of a {self.sensor} history must be None or a mapping "
                             f"sensor -> mask (None: complete) with the keys {list(names)}, got "
                             f"{type(masks).__name__}")
        for what, keys in (("matrix", set(matrices)), ("mask", None if masks is None else set(masks))):
            if keys is None:
                continue
            missing, extra = sorted(set(names) - keys), sorted(keys - set(names))
            if missing or extra:
                raise ValueError(
                    f"the {what} of a {self.sensor} history must have the keys {list(names)}: "
                    + "; ".join(([f"missing {missing}"] if missing else [])
                                + ([f"unknown {extra}"] if extra else [])))
        parts = {}
        for name in names:
            try:
                parts[name] = History(
                    sensor=name, matrix=matrices[name], object_positions=self.object_positions,
                    anchor_ids=self.anchor_ids, anchor_positions=self.anchor_positions,
                    robot_poses=self.robot_poses, mask=None if masks is None else masks[name],
                    meta=self.meta, timeline=self.timeline)
            except ValueError as exc:
                raise ValueError(f"{name} part of the {self.sensor} history: {exc}") from exc
        steps = {name: (p.n_objects, p.n_steps) for name, p in parts.items()}
        if len(set(steps.values())) > 1:
            raise ValueError(f"the sensors of a {self.sensor} history must hold the same objects "
                             f"and steps; (objects, steps) per sensor: {steps}")
        first = parts[names[0]]
        # plain dicts inside (a History pickles: joblib, multiprocessing); read-only views outside
        self.__dict__["_parts"] = parts
        self.__dict__["_data"] = {n: p.__dict__["_data"] for n, p in parts.items()}
        mask = {n: p.__dict__["_mask"] for n, p in parts.items()}  # as stored (dense or sparse)
        object.__setattr__(self, "mask", None if all(v is None for v in mask.values()) else mask)
        for name in ("object_positions", "anchor_ids", "anchor_positions", "robot_poses", "meta",
                     "timeline"):
            object.__setattr__(self, name, getattr(first, name))

    # ------------------------------------------------------------------ views
    @property
    def fused(self) -> bool:
        """Whether the history holds several sensors (:attr:`parts`)."""
        return "_parts" in self.__dict__

    @property
    def sensors(self) -> tuple[str, ...]:
        """The sensors whose histories this holds: ``(sensor,)``, or a fused set's, in
        :data:`SENSORS` order."""
        return tuple(self.__dict__["_parts"]) if self.fused else (self.sensor,)

    @property
    def parts(self) -> Mapping[str, History] | None:
        """A fused history's single-sensor histories (sensor -> History, the same ground truth);
        None for a single-sensor history."""
        parts = self.__dict__.get("_parts")
        return None if parts is None else MappingProxyType(parts)

    @property
    def dimension(self) -> int:
        """2 or 3: the dimension of the positions (and of the map built from the history)."""
        return self.object_positions.shape[1]

    @property
    def columns_per_step(self) -> int:
        """Matrix columns per step (of a fused history: over all its sensors)."""
        if self.fused:
            return sum(p.columns_per_step for p in self.parts.values())
        return step_columns(self.sensor, self.dimension)

    @property
    def n_objects(self) -> int:
        return self.shape[0]

    @property
    def n_steps(self) -> int:
        return self.shape[1] // self.columns_per_step

    @property
    def shape(self) -> tuple[int, int]:
        """(M, N * columns_per_step), without building the dense matrix (of a fused history: the
        columns of all its sensors)."""
        if self.fused:
            parts = list(self.parts.values())
            return (parts[0].shape[0], sum(p.shape[1] for p in parts))
        return tuple(self.__dict__["_data"].shape)

    @property
    def compact(self) -> bool:
        """Whether the matrix is stored compactly (sparse, or float32) rather than as float64 (of
        a fused history: any of its sensors')."""
        if self.fused:
            return any(p.compact for p in self.parts.values())
        data = self.__dict__["_data"]
        return compact.is_sparse(data) or data.dtype != np.float64

    @property
    def is_sparse(self) -> bool:
        """Whether the matrix is stored as a scipy sparse matrix (visibility, limited range); a
        fused history is not (see its :attr:`parts`)."""
        return not self.fused and compact.is_sparse(self.__dict__["_data"])

    @property
    def sparse(self):
        """The matrix as a float64 ``scipy.sparse.csr_array`` (zeros not stored): works at any size."""
        self._single("sparse")
        return compact.to_sparse(self.__dict__["_data"])

    @property
    def masked(self) -> bool:
        """Whether the history has a mask (without building a dense one)."""
        return self.__dict__["_mask"] is not None

    @property
    def partly_observed(self) -> bool:
        """Whether some entry went unobserved: a mask that is not all True (a limited view or
        range). Noise alone or a miss rate give a mask that is all True, and the mappers treat
        such a history as complete (``build_map`` and :class:`mappers.OnlineMapper` drop an
        all-True mask), so ``history.mask if history.partly_observed else None`` is the mask to
        pass them column by column. Works at any size: a sparse mask's stored True entries are
        counted in place, a dense one is read as it is (no copy in either form)."""
        self._single("partly_observed")
        mask = self.__dict__["_mask"]
        if mask is None:
            return False
        if sp.issparse(mask):
            return mask.count_nonzero() < mask.shape[0] * mask.shape[1]
        return not np.all(mask)

    @property
    def sparse_mask(self):
        """The mask as a bool ``scipy.sparse.csr_array`` (None without one): works at any size."""
        self._single("sparse_mask")
        mask = self.__dict__["_mask"]
        return None if mask is None else compact.to_sparse_mask(mask)

    def _single(self, what: str) -> None:
        if self.fused:
            raise ValueError(f"History.{what} is one matrix; a {self.sensor} history holds one per "
                             f"sensor: use History.parts[sensor].{what}")

    def dense(self, max_bytes: int | None = None) -> np.ndarray:
        """The (M, D) float64 matrix; for a compact history built once (cached) if it needs at most
        ``max_bytes`` (default :data:`lfmdr_gym.histories.compact.MAX_DENSE_BYTES`), else
        DenseTooLargeError. A fused history gives a read-only mapping sensor -> matrix."""
        if self.fused:
            return MappingProxyType({n: p.dense(max_bytes) for n, p in self.parts.items()})
        data = self.__dict__["_data"]
        if "_dense" not in self.__dict__:
            out = compact.to_dense(data, max_bytes)
            if out is data:
                return out
            self.__dict__["_dense"] = out
        return self.__dict__["_dense"]

    def replace(self, **changes: Any) -> History:
        """A new History with ``changes`` (any of its fields), the rest as stored.

        Use this rather than ``dataclasses.replace``, which reads ``matrix`` and ``mask`` through
        their properties and so densifies a compact history (or refuses one beyond the memory
        budget); here a compact matrix or mask is passed on as it is.
        """
        names = [f.name for f in fields(self)]
        unknown = sorted(set(changes) - set(names))
        if unknown:
            raise ValueError(f"History has no field(s) {unknown}; its fields are {names}")
        stored = {"matrix": self.__dict__["_data"],
                  "mask": self.__dict__["_mask"] if self.masked else None}
        values = {name: stored[name] if name in stored else getattr(self, name) for name in names}
        values.update(changes)
        return History(**values)

    __replace__ = replace  # copy.replace (Python 3.13 and later)

    def head(self, n_steps: int) -> History:
        """The history of the first ``n_steps`` steps (a checkpoint of the same episode)."""
        if not 0 < n_steps <= self.n_steps:
            raise ValueError(f"n_steps must be in [1, {self.n_steps}], got {n_steps}")
        if self.fused:
            heads = {n: p.head(n_steps) for n, p in self.parts.items()}
            return History(
                sensor=self.sensor, matrix={n: h.__dict__["_data"] for n, h in heads.items()},
                object_positions=self.object_positions, anchor_ids=self.anchor_ids,
                anchor_positions=self.anchor_positions,
                robot_poses=None if self.robot_poses is None else self.robot_poses[:n_steps],
                mask=None if not self.masked else {n: h.__dict__["_mask"] for n, h in heads.items()},
                meta=self.meta,
                timeline=None if self.timeline is None else self.timeline[:n_steps],
            )
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
        if self.fused:  # version 3: each sensor's matrix (and mask) under "<sensor>.<field>"
            version, per_sensor = 3, {"sensors": np.array(self.sensors)}
            for name, part in self.parts.items():
                per_sensor.update({f"{name}.{k}": v for k, v in
                                   compact.compact_fields(part.__dict__["_data"]).items()})
                if part.masked:
                    per_sensor.update({f"{name}.{k}": v for k, v in
                                       compact.mask_fields(part.__dict__["_mask"]).items()})
        else:  # version 1 where it suffices, so that older lfmdr still reads today's dense files
            mask = self.__dict__["_mask"]
            version = 3 if compact.is_sparse(mask) else 2 if self.compact else 1
            per_sensor = compact.compact_fields(self.__dict__["_data"])
            if mask is not None:
                per_sensor.update(compact.mask_fields(mask))
        if self.dimension == 3:  # only 3-D files need version 4; 2-D files are as before
            version = 4
        arrays: dict[str, np.ndarray] = {
            "format": np.array(FORMAT),
            "format_version": np.array(version),
            "sensor": np.array(self.sensor),
            **per_sensor,
            "object_positions": self.object_positions,
            "anchor_ids": self.anchor_ids,
            "anchor_positions": self.anchor_positions,
            "meta": np.array(json.dumps(self.meta, sort_keys=True)),
        }
        if self.robot_poses is not None:
            arrays["robot_poses"] = self.robot_poses
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
                version = _version(data["format_version"], path)
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
            sensor = str(fields["sensor"])
            if version >= 3 and sensor in FUSED_SENSORS:  # (4 is 3 with 3-D positions)
                names = _names(fields["sensors"])
                parts = {n: {k[len(n) + 1:]: v for k, v in fields.items() if k.startswith(n + ".")}
                         for n in names}
                for n, part in parts.items():
                    if "matrix" not in part and "matrix_shape" not in part:
                        raise KeyError(f"{n}.matrix")
                matrix = {n: compact.from_fields(part) for n, part in parts.items()}
                mask = {n: compact.mask_from_fields(part) for n, part in parts.items()}
            else:
                matrix, mask = compact.from_fields(fields), compact.mask_from_fields(fields)
            return cls(
                sensor=sensor,
                matrix=matrix,
                object_positions=fields["object_positions"],
                anchor_ids=fields["anchor_ids"],
                anchor_positions=fields["anchor_positions"],
                robot_poses=fields.get("robot_poses"),
                mask=mask,
                meta=_meta(fields["meta"]),
                timeline=fields.get("timeline"),
            )
        except KeyError as exc:
            raise HistoryFileError(f"{path} lacks the field {exc.args[0]!r}") from exc
        except (ValueError, TypeError, OverflowError) as exc:
            # TypeError / OverflowError: a field of the wrong kind (a 2-D array where a number
            # belongs, a count beyond int64) that the checks above do not name
            raise HistoryFileError(f"{path} holds an inconsistent history: {exc}") from exc


def _version(value: np.ndarray, path: Path) -> int:
    """The format version a file states: a single integer, nothing else read as one."""
    value = np.asarray(value)
    if value.shape != () or value.dtype.kind not in "iu":
        raise HistoryFileError(f"{path} states no integer format version (got {value.dtype} "
                               f"of shape {value.shape})")
    return int(value)


def _names(value: np.ndarray) -> list[str]:
    """The sensors a fused history's file lists: a 1-D array of strings."""
    value = np.asarray(value)
    if value.ndim != 1 or value.dtype.kind != "U":
        raise ValueError(f"'sensors' must list the fused sensors' names, got {value.dtype} of "
                         f"shape {value.shape}")
    return [str(n) for n in value]


def _meta(value: np.ndarray) -> dict:
    """The file's meta data: one JSON object (as :meth:`History.save` writes it)."""
    value = np.asarray(value)
    if value.shape != () or value.dtype.kind != "U":
        raise ValueError(f"'meta' must be one JSON string, got {value.dtype} of shape {value.shape}")
    meta = json.loads(str(value))  # a json.JSONDecodeError is a ValueError
    if not isinstance(meta, dict):
        raise ValueError(f"'meta' must hold a JSON object, got {type(meta).__name__}")
    return meta


def _mask_get(self: History) -> Any:
    mask = self.__dict__["_mask"]
    if mask is None or isinstance(mask, np.ndarray):
        return mask
    if isinstance(mask, Mapping):  # fused: each sensor's mask as its part gives it, read-only
        return MappingProxyType({n: p.mask for n, p in self.parts.items()})
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
# ``mask`` likewise: kept as stored (dense or sparse); reading it gives the dense bool array (of a
# fused history: a read-only mapping sensor -> its part's mask).
History.mask = property(_mask_get, _mask_set, doc="The (M, D) bool mask or None (History.sparse_mask).")
