"""Sightings -> history steps and cells: the one binning of logged observations.

Logged data (an MRCLAM run, an observation table) is a list of sightings: which robot saw which
landmark when, with what reading. A :class:`~lfmdr_gym.histories.history.History` wants steps
(columns) and landmarks (rows). This module makes the steps and fills the cells, vectorised
(no Python loop per row or per cell), for every source of sightings:

* :func:`time_steps`: per-robot time bins of ``bin_width`` seconds on one grid that starts at
  the earliest time of all robots (``t0``); the robots' bins are concatenated (robot 0's, then
  robot 1's, ...) and the timeline keeps each bin's robot and grid index (tick). Bins in which a
  robot saw nothing can be dropped (``drop_empty_bins``).
* :func:`tick_steps`: one step per distinct (robot, tick) pair, ticks given (a frame number).
* :func:`cell_values`: each sensor's value of every (landmark, step) cell that was sighted --
  visibility 1, bearing the circular mean (the normalised sum of the unit vectors), range the
  median -- and which cells hold a value.
* :func:`assemble`: those cells as the (M, N * columns) matrix and mask a History takes, dense
  or (large) ``scipy.sparse``.

Sums are taken in row order (``np.bincount`` accumulates in input order, as ``np.add.at``
does), and a median of an even count is ``(a + b) / 2`` as :func:`numpy.median` computes it,
so the values are bit for bit those of a per-cell loop over the same rows.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from lfmdr_gym.checks import check_real
from lfmdr_gym.histories.compact import COMPACT_ABOVE_BYTES
from mappers.core.sensors import COLUMNS_PER_STEP, check_sensor

__all__ = ["Cells", "Steps", "assemble", "cell_values", "tick_steps", "time_steps"]

MIN_BEARING_NORM = 1e-12
"""A cell whose bearing unit vectors sum to a shorter vector has no mean bearing (they cancel):
it is left unobserved."""


@dataclass(frozen=True)
class Steps:
    """Rows -> steps.

    Attributes:
        step: (n,) int64 step of each row.
        timeline: (N, 2) int64 robot (position, 0-based) and tick of every step, in step order
            (robot, then tick).
        ticks_per_robot: length of the per-robot tick grid (steps ``robot * ticks_per_robot +
            tick`` before empty ones are dropped).
    """

    step: np.ndarray
    timeline: np.ndarray
    ticks_per_robot: int

    @property
    def n_steps(self) -> int:
        return len(self.timeline)


def _check_rows(robot: np.ndarray, n_robots: int, n: int) -> np.ndarray:
    robot = np.asarray(robot)
    if robot.shape != (n,) or not np.issubdtype(robot.dtype, np.integer):
        raise ValueError(f"robot must be ({n},) integer positions, got {robot.dtype} {robot.shape}")
    if n and (robot.min() < 0 or robot.max() >= n_robots):
        raise ValueError(f"robot positions must be in [0, {n_robots}), got "
                         f"[{robot.min()}, {robot.max()}]")
    return robot.astype(np.int64, copy=False)


def _steps_from_ticks(robot: np.ndarray, tick: np.ndarray, n_robots: int, n_ticks: int,
                      drop_empty: bool) -> Steps:
    """Steps of the (robot, tick) grid: every grid point, or only those with a row."""
    if not drop_empty:
        used = np.arange(n_robots * n_ticks, dtype=np.int64)
        step = robot * n_ticks + tick
        return Steps(step, np.column_stack([used // n_ticks, used % n_ticks]), n_ticks)
    if n_robots * n_ticks < 2**62:  # one int64 key per row: np.unique sorts it by robot, tick
        used, step = np.unique(robot * n_ticks + tick, return_inverse=True)
        timeline = np.column_stack([used // n_ticks, used % n_ticks])
        return Steps(np.asarray(step, np.int64).ravel(), timeline.astype(np.int64), n_ticks)
    order = np.lexsort((tick, robot))  # ticks too large for one key: sort the pairs
    r, t = robot[order], tick[order]
    new = np.r_[True, (r[1:] != r[:-1]) | (t[1:] != t[:-1])] if len(r) else np.zeros(0, bool)
    step = np.empty(len(r), dtype=np.int64)
    step[order] = np.cumsum(new) - 1
    return Steps(step, np.column_stack([r[new], t[new]]).astype(np.int64), n_ticks)


def time_steps(robot: np.ndarray, time: np.ndarray, n_robots: int, bin_width: float, *,
               drop_empty_bins: bool = True) -> Steps:
    """Per-robot time bins of ``bin_width`` seconds as steps.

    The grid starts at the earliest time of all rows (``t0``); row ``i`` falls into tick
    ``floor((time[i] - t0) / bin_width)`` of robot ``robot[i]`` (its position, 0-based, among
    ``n_robots``). Steps are the robots' bins in order (robot 0's ticks, then robot 1's, ...):
    those with a row (``drop_empty_bins``), or every tick of the grid of every robot.
    """
    bin_width = check_real("bin_width", bin_width, low=0.0, low_open=True)  # [s]
    time = np.asarray(time, dtype=np.float64)
    if time.ndim != 1 or not time.size:
        raise ValueError(f"time must be a non-empty 1-D array, got shape {time.shape}")
    robot = _check_rows(robot, n_robots, len(time))
    t0 = time.min()
    n_ticks = int(np.floor((time.max() - t0) / bin_width)) + 1
    tick = np.floor((time - t0) / bin_width).astype(np.int64)
    return _steps_from_ticks(robot, tick, n_robots, n_ticks, drop_empty_bins)


def tick_steps(robot: np.ndarray, tick: np.ndarray, n_robots: int, *,
               extra: np.ndarray | None = None) -> Steps:
    """One step per distinct (robot, tick) pair of the rows (and of ``extra``, an (E, 2) array of
    (robot, tick) steps that hold no row), in order of robot, then tick. Ticks are non-negative
    integers (a frame number)."""
    tick = np.asarray(tick)
    if tick.ndim != 1 or not np.issubdtype(tick.dtype, np.integer):
        raise ValueError(f"tick must be a 1-D integer array, got {tick.dtype} {tick.shape}")
    robot = _check_rows(robot, n_robots, len(tick))
    n = len(tick)
    if extra is not None and len(extra):
        extra = np.asarray(extra, dtype=np.int64).reshape(-1, 2)
        _check_rows(extra[:, 0], n_robots, len(extra))
        robot, tick = np.r_[robot, extra[:, 0]], np.r_[tick, extra[:, 1]]
    if len(tick) and tick.min() < 0:
        raise ValueError(f"ticks (frame numbers) must be >= 0, got {tick.min()}")
    n_ticks = int(tick.max()) + 1 if len(tick) else 1
    steps = _steps_from_ticks(robot, tick.astype(np.int64), n_robots, n_ticks, True)
    return Steps(steps.step[:n], steps.timeline, steps.ticks_per_robot)


@dataclass(frozen=True)
class Cells:
    """The sighted (landmark, step) cells of a log and each sensor's value in them.

    Attributes:
        shape: (M, N) landmarks x steps.
        landmark, step: (C,) int64 landmark and step of each cell, sorted by landmark then step.
        values: sensor -> (C,) values (visibility, range) or (C, 2) (bearing: cos, sin).
        observed: sensor -> (C,) bool, the cells in which the sensor has a value (a bearing mean
            of unit vectors that cancel has none).
    """

    shape: tuple[int, int]
    landmark: np.ndarray
    step: np.ndarray
    values: dict[str, np.ndarray]
    observed: dict[str, np.ndarray]


def _median_by_cell(cell: np.ndarray, value: np.ndarray, n_cells: int) -> np.ndarray:
    """The median of ``value`` over the rows of each cell, as :func:`numpy.median` gives it (the
    middle value, or of an even count the two middle ones summed and halved)."""
    count = np.bincount(cell, minlength=n_cells)
    out = np.zeros(n_cells)
    single = count[cell] == 1
    out[cell[single]] = value[single]  # most cells hold one reading: no sort needed
    rows = np.flatnonzero(~single)
    if len(rows):
        order = rows[np.lexsort((value[rows], cell[rows]))]
        v, multi = value[order], np.flatnonzero(count > 1)
        n = count[multi]
        start = np.r_[0, np.cumsum(n)[:-1]]
        hi, lo = v[start + n // 2], v[start + (n - 1) // 2]
        out[multi] = np.where(n % 2 == 1, hi, (lo + hi) / 2)
    return out


def cell_values(sensors: tuple[str, ...], landmark: np.ndarray, step: np.ndarray,
                shape: tuple[int, int], *, bearing: np.ndarray | None = None,
                bearing_unit: np.ndarray | None = None, range_: np.ndarray | None = None,
                visible: np.ndarray | None = None) -> Cells:
    """Each sensor's value in every sighted (landmark, step) cell.

    Args:
        sensors: the sensors to fill (names of :data:`mappers.core.sensors.SENSORS`).
        landmark, step: (n,) int row and step of every sighting.
        shape: (M, N) landmarks x steps.
        bearing: (n,) bearing angles [rad]; a cell's bearing is the circular mean
            ``(sum cos, sum sin) / |(sum cos, sum sin)|`` (normalised even for one sighting).
        bearing_unit: (n, 2) bearings as unit vectors (cos, sin), instead of ``bearing``: a cell
            with one sighting keeps it exactly as given, several are averaged as above.
        range_: (n,) ranges [m]; a cell's range is the median of its sightings.
        visible: (n,) bool, whether the sighting saw the landmark (None: every row did); a
            cell's visibility is 1 if any row of it did, else 0 (observed, not seen).
    """
    m, n_steps = (int(shape[0]), int(shape[1]))
    landmark = np.asarray(landmark, dtype=np.int64)
    step = np.asarray(step, dtype=np.int64)
    key = landmark * n_steps + step
    cells, cell = np.unique(key, return_inverse=True)
    cell = np.asarray(cell, np.int64).ravel()
    n_cells = len(cells)
    values: dict[str, np.ndarray] = {}
    observed: dict[str, np.ndarray] = {}
    for sensor in sensors:
        check_sensor(sensor)
        if sensor == "visibility":
            seen = (np.ones(n_cells, dtype=bool) if visible is None else
                    np.bincount(cell, weights=np.asarray(visible, bool), minlength=n_cells) > 0)
            values[sensor], observed[sensor] = seen.astype(np.float64), np.ones(n_cells, bool)
        elif sensor == "bearing":
            if bearing_unit is not None:
                cos, sin = bearing_unit[:, 0], bearing_unit[:, 1]
            elif bearing is not None:
                cos, sin = np.cos(bearing), np.sin(bearing)
            else:
                raise ValueError("the bearing sensor needs bearing readings")
            c = np.bincount(cell, weights=cos, minlength=n_cells)
            s = np.bincount(cell, weights=sin, minlength=n_cells)
            norm = np.hypot(c, s)
            ok = norm > MIN_BEARING_NORM
            c = np.where(ok, c / np.where(ok, norm, 1), 0.0)
            s = np.where(ok, s / np.where(ok, norm, 1), 0.0)
            if bearing_unit is not None:  # a single given unit vector is kept bit for bit
                single = np.bincount(cell, minlength=n_cells) == 1
                rows = np.flatnonzero(single[cell])
                c[cell[rows]], s[cell[rows]] = cos[rows], sin[rows]
                ok[cell[rows]] = True
            values[sensor], observed[sensor] = np.column_stack([c, s]), ok
        elif sensor == "range":
            if range_ is None:
                raise ValueError("the range sensor needs range readings")
            values[sensor] = _median_by_cell(cell, np.asarray(range_, np.float64), n_cells)
            observed[sensor] = np.ones(n_cells, bool)
    return Cells((m, n_steps), cells // n_steps, cells % n_steps, values, observed)


def assemble(cells: Cells, sensor: str, *, masked: bool = True,
             sparse: bool | None = None) -> tuple[np.ndarray | sp.csr_array,
                                                  np.ndarray | sp.csr_array | None]:
    """One sensor's (matrix, mask) of shape (M, N * columns per step) from its cells.

    Unsighted cells read 0. ``masked``: the mask is True exactly where the sensor has a value
    (only sightings are known); else None (every absent cell is a known 0, as an env without
    limits records). ``sparse``: a ``scipy.sparse.csr_array`` matrix (and mask) instead of dense
    arrays; None chooses sparse when the dense float64 matrix would exceed
    :data:`~lfmdr_gym.histories.compact.COMPACT_ABOVE_BYTES`.
    """
    m, n_steps = cells.shape
    cols = COLUMNS_PER_STEP[sensor]
    ok = cells.observed[sensor]
    value = cells.values[sensor].reshape(len(ok), cols)
    if sparse is None:
        sparse = 8 * m * n_steps * cols > COMPACT_ABOVE_BYTES
    rows = np.repeat(cells.landmark, cols)
    col = (cells.step[:, None] * cols + np.arange(cols)).ravel()
    data = np.where(ok[:, None], value, 0.0).ravel()
    keep = np.repeat(ok, cols)
    shape = (m, n_steps * cols)
    if sparse:
        nz = data != 0
        matrix = sp.csr_array((data[nz], (rows[nz], col[nz])), shape=shape)
        mask = (sp.csr_array((np.ones(int(keep.sum()), bool), (rows[keep], col[keep])),
                             shape=shape) if masked else None)
        return matrix, mask
    matrix = np.zeros(shape)
    matrix[rows, col] = data
    mask = None
    if masked:
        mask = np.zeros(shape, dtype=bool)
        mask[rows[keep], col[keep]] = True
    return matrix, mask
