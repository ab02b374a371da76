"""A uniform cell grid over static points: which points lie near a query, in time independent of M.

The arena is cut into square cells at least as wide as the largest distance a query needs; a
point within that distance of a query then lies in the query's cell or one of its eight
neighbours. Each cell keeps the sorted ids of the points in its 3 x 3 block, so one lookup hands
back a short candidate list in ascending id order (the order a scan of all M points would give,
which keeps every reading bit-identical to the full scan). Built once per layout, in O(M).

Also here: :func:`sample_separated`, rejection sampling of points at least a distance apart with a
background grid of cells of side ``separation / sqrt(2)`` (at most one point per cell), as in
Bridson, "Fast Poisson disk sampling in arbitrary dimensions" (SIGGRAPH sketches 2007), so each
candidate is checked against the few accepted points nearby instead of all of them.
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ["CellGrid", "sample_separated"]


class CellGrid:
    """Points (M, 2) inside the square ``[-half, half]^2`` binned into cells of side >= ``reach``.

    :meth:`near` returns the ascending ids of every point within ``reach`` of a query point inside
    the square (and some farther ones): the caller filters by exact distance.
    """

    def __init__(self, points: np.ndarray, half: float, reach: float) -> None:
        if not reach > 0.0:
            raise ValueError(f"reach must be > 0, got {reach}")
        self.half = float(half)
        # cells per side, each wider than reach (by a margin over rounding)
        self.n_cells = max(1, int(2.0 * self.half / (reach * (1.0 + 1e-9))))
        self.inv_cell = self.n_cells / (2.0 * self.half)
        cx, cy = self._cells(points[:, 0], points[:, 1])
        n = self.n_cells
        cell_ids = cy * n + cx
        order = np.argsort(cell_ids, kind="stable")
        starts = np.searchsorted(cell_ids[order], np.arange(n * n + 1))
        members = [order[starts[c]:starts[c + 1]] for c in range(n * n)]
        empty = np.zeros(0, dtype=np.int64)
        self._blocks: list[np.ndarray] = []
        for iy in range(n):
            for ix in range(n):
                parts = [members[jy * n + jx]
                         for jy in range(max(iy - 1, 0), min(iy + 2, n))
                         for jx in range(max(ix - 1, 0), min(ix + 2, n))]
                block = np.sort(np.concatenate(parts)) if parts else empty
                self._blocks.append(block.astype(np.int64, copy=False))
        # each block's points too (points[block]), so a query needs no gather
        self._block_points = [np.ascontiguousarray(points[b], dtype=np.float64)
                              for b in self._blocks]

    def _cells(self, x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        last = self.n_cells - 1
        cx = np.clip(((x + self.half) * self.inv_cell).astype(np.int64), 0, last)
        cy = np.clip(((y + self.half) * self.inv_cell).astype(np.int64), 0, last)
        return cx, cy

    def _block(self, x: float, y: float) -> int:
        last = self.n_cells - 1
        ix = min(max(int((x + self.half) * self.inv_cell), 0), last)
        iy = min(max(int((y + self.half) * self.inv_cell), 0), last)
        return iy * self.n_cells + ix

    def near(self, x: float, y: float) -> np.ndarray:
        """Ascending ids of the points in the 3 x 3 block of cells around ``(x, y)`` (read-only)."""
        return self._blocks[self._block(x, y)]

    def near_points(self, x: float, y: float) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`near` and those points' coordinates (K, 2), both kept by the grid: read-only."""
        b = self._block(x, y)
        return self._blocks[b], self._block_points[b]


def sample_separated(
    rng: np.random.Generator, n: int, half: float, separation: float, batch: int, budget: int
) -> tuple[np.ndarray, int]:
    """Up to ``n`` uniform points in ``[-half, half]^2`` pairwise >= ``separation`` apart.

    Candidates are drawn ``batch`` at a time from ``rng`` and accepted in order when no accepted
    point is nearer than ``separation`` (squared distances ``dx*dx + dy*dy``, compared with
    ``separation**2``), until ``n`` are accepted or ``budget`` candidates were drawn: the same
    draws and decisions as a check against every accepted point. Returns the points accepted
    (k, 2) and the number of candidates drawn.
    """
    s2 = separation * separation
    # A cell's diagonal is just under `separation`, so a cell holds at most one accepted point,
    # and points within `separation` of a candidate lie at most 2 cells away in x and in y.
    cell = separation / math.sqrt(2.0) * (1.0 - 1e-9)
    side = max(1, math.ceil(2.0 * half / cell))
    owner = np.full((side + 4, side + 4), -1, dtype=np.int64)  # 2 cells of padding on each side
    pts = np.empty((n, 2))
    k = drawn = 0
    while k < n and drawn < budget:
        cand = rng.uniform(-half, half, size=(batch, 2))
        drawn += batch
        cells = np.minimum(((cand + half) / cell).astype(np.int64), side - 1) + 2
        for (px, py), (cx, cy) in zip(cand.tolist(), cells.tolist(), strict=True):
            block = owner[cx - 2:cx + 3, cy - 2:cy + 3]
            ok = True
            for j in block[block >= 0].tolist():
                dx, dy = px - pts[j, 0], py - pts[j, 1]
                if dx * dx + dy * dy < s2:
                    ok = False
                    break
            if ok:
                pts[k] = px, py
                owner[cx, cy] = k
                k += 1
                if k == n:
                    break
    return pts[:k], drawn
