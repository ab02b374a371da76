"""Pictures of the arena drawn with numpy alone (no plotting library needed).

:func:`draw_frame` is a pure function of the geometry and the current readings, so it draws
logged data as well as the live environment. :class:`HumanViewer` shows frames in a pygame
window for ``render_mode="human"`` (optional extra: ``pip install "lfmdr[human]"``).
"""

from __future__ import annotations

import os
import sys

import numpy as np
from numpy.typing import ArrayLike

from lfmdr_gym.sim.sensors import ray_directions

__all__ = ["HumanViewer", "draw_ellipses", "draw_frame", "draw_map", "ellipse_outlines",
           "human_rendering_error"]

BACKGROUND = (250, 250, 247)
WALL = (60, 60, 60)
OBJECT = (150, 150, 150)
SENSED = (30, 160, 60)
ANCHOR = (210, 40, 40)
ROBOT = (40, 90, 200)
HEADING = (10, 10, 40)
SIGHT = (120, 200, 140)
BEARING_RAY = (205, 215, 235)
PROXIMITY_RAY = (240, 150, 40)
ESTIMATE = (40, 90, 200)
ERROR_LINE = (230, 120, 120)
ELLIPSE = (120, 150, 225)


class _Canvas:
    """An (H, W, 3) uint8 image with world coordinates: x right, y up, square arena of half-side a."""

    def __init__(self, size: int, arena_half: float, margin: int = 6) -> None:
        self.img = np.empty((size, size, 3), dtype=np.uint8)
        self.img[:] = BACKGROUND
        self.size = size
        self.margin = margin
        self.scale = (size - 1 - 2 * margin) / (2.0 * arena_half)
        self.a = arena_half

    def to_px(self, xy: np.ndarray) -> np.ndarray:
        """World points (..., 2) -> pixel (col, row) floats."""
        xy = np.asarray(xy, dtype=np.float64)
        col = self.margin + (xy[..., 0] + self.a) * self.scale
        row = self.margin + (self.a - xy[..., 1]) * self.scale
        return np.stack([col, row], axis=-1)

    def lines(self, start: np.ndarray, end: np.ndarray, color: tuple[int, int, int]) -> None:
        """Straight 1-px lines from each start (K, 2) to each end (K, 2), world coordinates."""
        start, end = np.atleast_2d(start), np.atleast_2d(end)
        if start.size == 0:
            return
        p0, p1 = self.to_px(start), self.to_px(end)
        n = int(np.ceil(np.abs(p1 - p0).max())) + 1
        t = np.linspace(0.0, 1.0, n)[None, :, None]
        pts = np.rint(p0[:, None, :] + t * (p1 - p0)[:, None, :]).astype(np.int64).reshape(-1, 2)
        keep = ((pts >= 0) & (pts < self.size)).all(axis=1)
        pts = pts[keep]
        self.img[pts[:, 1], pts[:, 0]] = color

    def discs(self, centres: np.ndarray, radius_m: float, color: tuple[int, int, int],
              min_px: float = 1.5, ring: bool = False) -> None:
        """Filled discs (or 2-px rings) of ``radius_m`` around world ``centres`` (K, 2)."""
        centres = np.atleast_2d(centres)
        if centres.size == 0:
            return
        rad = max(radius_m * self.scale, min_px)
        span = int(np.ceil(rad)) + 1
        off = np.arange(-span, span + 1)
        dc, dr = np.meshgrid(off, off)
        # One stencil for every disc: the sub-pixel centre is ignored, the picture is a sketch
        d2 = dc**2 + dr**2
        stencil = d2 <= rad * rad
        if ring:
            stencil &= d2 >= (rad - 2.0) ** 2
        for c, r in np.rint(self.to_px(centres)).astype(np.int64):
            cols, rows = c + dc, r + dr
            mask = stencil & (cols >= 0) & (cols < self.size) & (rows >= 0) & (rows < self.size)
            self.img[rows[mask], cols[mask]] = color


def draw_frame(
    *,
    arena_half: float,
    object_positions: ArrayLike,
    object_radius: float,
    robot_pose: ArrayLike,
    robot_radius: float,
    anchor_ids: ArrayLike = (),
    sensor: str | None = None,
    reading: ArrayLike | None = None,
    proximity: ArrayLike | None = None,
    size: int = 480,
    observed: ArrayLike | None = None,
) -> np.ndarray:
    """Draw the arena as an (size, size, 3) uint8 RGB image.

    Shows the walls, the objects (anchors ringed in red), the robot and its heading, and what it
    senses now: for ``"visibility"`` the visible objects in green with their lines of sight; for
    ``"bearing"`` a faint ray to every object; for ``"range"`` a ray to every object sensed
    (non-zero reading); and the proximity ring's rays (orange) up to what each one hit. With
    ``observed`` (imperfect sensing: the objects the sensor reported on), bearing rays go to
    those objects only, drawn as sensed.
    """
    if size < 32:
        raise ValueError(f"size must be >= 32 pixels, got {size}")
    obj = np.asarray(object_positions, dtype=np.float64).reshape(-1, 2)
    pose = np.asarray(robot_pose, dtype=np.float64)
    robot = pose[:2]
    canvas = _Canvas(size, arena_half)
    a = arena_half
    corners = np.array([(-a, -a), (a, -a), (a, a), (-a, a)])
    canvas.lines(corners, np.roll(corners, -1, axis=0), WALL)

    sensed = np.zeros(obj.shape[0], dtype=bool)
    if sensor is not None and reading is not None:
        rd = np.asarray(reading)
        if sensor == "visibility":
            sensed = rd.reshape(-1).astype(bool)
            canvas.lines(np.repeat(robot[None], sensed.sum(), 0), obj[sensed], SIGHT)
        elif sensor == "bearing":
            if observed is not None:
                sensed = np.asarray(observed).reshape(-1).astype(bool)
            rays = sensed if observed is not None else np.ones(obj.shape[0], dtype=bool)
            canvas.lines(np.repeat(robot[None], rays.sum(), 0), obj[rays], BEARING_RAY)
        elif sensor == "range":
            sensed = rd.reshape(-1) > 0
            canvas.lines(np.repeat(robot[None], sensed.sum(), 0), obj[sensed], BEARING_RAY)
        else:
            raise ValueError(f"unknown sensor {sensor!r}")
    if proximity is not None:
        prox = np.asarray(proximity, dtype=np.float64).reshape(-1)
        c, s = np.cos(pose[2]), np.sin(pose[2])
        u = ray_directions(prox.size) @ np.array(((c, s), (-s, c)))
        canvas.lines(np.repeat(robot[None], prox.size, 0), robot + u * prox[:, None], PROXIMITY_RAY)

    canvas.discs(obj[~sensed], object_radius, OBJECT)
    canvas.discs(obj[sensed], object_radius, SENSED)
    ids = np.asarray(anchor_ids, dtype=np.int64).reshape(-1)
    canvas.discs(obj[ids], object_radius * 2.2, ANCHOR, min_px=4.0, ring=True)
    canvas.discs(robot, robot_radius, ROBOT)
    # heading: a 3-px wide stroke from the centre to twice the robot's radius
    ahead = np.array((np.cos(pose[2]), np.sin(pose[2])))
    side = np.array((-ahead[1], ahead[0])) / canvas.scale  # one pixel sideways, in metres
    for k in (-1.0, 0.0, 1.0):
        canvas.lines(robot + k * side, robot + k * side + 2.0 * robot_radius * ahead, HEADING)
    return canvas.img


def ellipse_outlines(positions: ArrayLike, covariances: ArrayLike, *, level: float = 0.95,
                     n_points: int = 48) -> np.ndarray:
    """The ``level`` region of each object's Gaussian as a closed outline (M, n_points + 1, 2):
    ``position + sqrt(q) L u`` for unit vectors ``u`` around the circle, ``L L^T`` the (2, 2)
    covariance (its eigen-decomposition, so a singular one gives a segment) and ``q`` the
    chi-squared(2) ``level`` quantile. Rows whose position or covariance is not finite, or whose
    covariance is zero (anchors), are NaN (nothing to draw). Only the first two coordinates are
    drawn (the plan view of a 3-D map, its covariance's x-y block)."""
    from scipy.stats import chi2

    pos = np.asarray(positions, dtype=np.float64)
    cov = np.asarray(covariances, dtype=np.float64)
    if pos.ndim != 2 or cov.shape != (len(pos), pos.shape[1], pos.shape[1]) or pos.shape[1] < 2:
        raise ValueError(f"covariances must have shape (M, d, d) for positions (M, d), got "
                         f"{cov.shape} for {pos.shape}")
    if not 0.0 < level < 1.0:
        raise ValueError(f"level must be in (0, 1), got {level}")
    pos, cov = pos[:, :2], cov[:, :2, :2]
    ok = np.all(np.isfinite(pos), axis=1) & np.all(np.isfinite(cov), axis=(1, 2))
    ok &= np.abs(cov).reshape(len(cov), -1).max(axis=1, initial=0.0) > 0
    out = np.full((len(pos), n_points + 1, 2), np.nan)
    if not ok.any():
        return out
    ev, vec = np.linalg.eigh(0.5 * (cov[ok] + cov[ok].transpose(0, 2, 1)))
    axes = vec * np.sqrt(np.maximum(ev, 0.0) * chi2.ppf(level, 2))[:, None, :]  # columns
    a = np.linspace(0.0, 2 * np.pi, n_points + 1)
    circle = np.stack([np.cos(a), np.sin(a)], axis=1)  # (n + 1, 2)
    out[ok] = pos[ok][:, None, :] + np.einsum("mij,nj->mni", axes, circle)
    return out


def draw_ellipses(ax, positions: ArrayLike, covariances: ArrayLike, *, level: float = 0.95,
                  **line_kwargs):
    """Draw each object's ``level`` (95 %) ellipse (:func:`ellipse_outlines`) on the matplotlib
    axes ``ax`` as thin lines (``line_kwargs`` override the colour and width); returns the
    number of ellipses drawn."""
    outlines = ellipse_outlines(positions, covariances, level=level)
    style = {"color": "tab:blue", "lw": 0.6, "alpha": 0.7, **line_kwargs}
    drawn = 0
    for line in outlines:
        if np.isfinite(line[0, 0]):
            ax.plot(line[:, 0], line[:, 1], **style)
            drawn += 1
    return drawn


def draw_map(
    *,
    arena_half: float,
    estimates: ArrayLike,
    object_radius: float,
    truth: ArrayLike | None = None,
    anchor_ids: ArrayLike = (),
    size: int = 480,
    view_half: float | None = None,
    covariances: ArrayLike | None = None,
) -> np.ndarray:
    """Draw a map as an (size, size, 3) uint8 RGB image, in the arena's frame.

    The estimated positions (M, 2) are blue discs (NaN rows, objects not mapped yet, are left
    out); with ``truth`` (M, 2) the true objects are grey and a red line joins each estimate to
    its truth; anchors are ringed in red at their (known) positions. ``view_half``: half-side
    [m] of the square drawn, centred on the arena (default ``arena_half``; larger shows the
    estimates that fall outside the arena, the walls then drawn smaller). ``covariances``
    ((M, 2, 2), ``Map.covariances``): each estimate's 95 % ellipse in pale blue
    (:func:`ellipse_outlines`).
    """
    if size < 32:
        raise ValueError(f"size must be >= 32 pixels, got {size}")
    est = np.asarray(estimates, dtype=np.float64).reshape(-1, 2)
    canvas = _Canvas(size, arena_half if view_half is None else max(view_half, arena_half))
    a = arena_half
    corners = np.array([(-a, -a), (a, -a), (a, a), (-a, a)])
    canvas.lines(corners, np.roll(corners, -1, axis=0), WALL)
    placed = np.all(np.isfinite(est), axis=1)
    ids = np.asarray(anchor_ids, dtype=np.int64).reshape(-1)
    if truth is not None:
        true = np.asarray(truth, dtype=np.float64).reshape(-1, 2)
        canvas.discs(true, object_radius, OBJECT)
        canvas.lines(true[placed], est[placed], ERROR_LINE)
    if covariances is not None:
        outlines = ellipse_outlines(est, covariances)
        outlines = outlines[np.isfinite(outlines[:, 0, 0])]
        canvas.lines(outlines[:, :-1].reshape(-1, 2), outlines[:, 1:].reshape(-1, 2), ELLIPSE)
    canvas.discs(est[placed], object_radius, ESTIMATE)
    ring = est[ids] if truth is None else np.asarray(truth, dtype=np.float64).reshape(-1, 2)[ids]
    canvas.discs(ring[np.all(np.isfinite(ring), axis=1)], object_radius * 2.2, ANCHOR,
                 min_px=4.0, ring=True)
    return canvas.img


class _RenderModes(list):
    """The render modes this machine can show (iterating gives them: Gymnasium's ``check_env``
    renders each), which also answers yes to ``"human" in modes`` where "human" cannot work,
    so that ``gym.make(id, render_mode="human")`` hands "human" to the env, whose error says
    what is missing (``pip install "lfmdr[human]"``, or a display), instead of wrapping the env
    in Gymnasium's HumanRendering, which fails at the first step asking for
    ``gymnasium[classic-control]``."""

    def __contains__(self, mode: object) -> bool:
        return mode == "human" or super().__contains__(mode)


def available_render_modes() -> list[str]:
    """``"rgb_array"`` always (pure numpy), ``"human"`` where pygame and a display exist (the
    list answers yes to ``"human" in ...`` regardless: see :class:`_RenderModes`)."""
    return _RenderModes(["rgb_array"] if human_rendering_error() is not None
                        else ["rgb_array", "human"])


def human_rendering_error() -> Exception | None:
    """Why ``render_mode="human"`` cannot work here (an exception to raise), or None if it can."""
    try:
        import pygame  # noqa: F401
    except ImportError:
        from gymnasium.error import DependencyNotInstalled

        return DependencyNotInstalled(
            'render_mode="human" needs pygame: pip install "lfmdr[human]" '
            '(or use render_mode="rgb_array", which needs nothing extra)'
        )
    if sys.platform.startswith("linux") and not (
        os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY") or os.environ.get("SDL_VIDEODRIVER")
    ):
        return RuntimeError(
            'render_mode="human" needs a display (no DISPLAY or WAYLAND_DISPLAY is set); '
            'use render_mode="rgb_array" on a headless machine (pip install "lfmdr[human]" on a desktop)'
        )
    return None


class HumanViewer:
    """A pygame window showing frames at ``fps``."""

    def __init__(self, size: int, fps: int, title: str = "lfmdr") -> None:
        err = human_rendering_error()
        if err is not None:
            raise err
        import pygame

        self._pygame = pygame
        pygame.display.init()  # only the display: pygame.init() would open audio devices too
        pygame.display.set_caption(title)
        self.screen = pygame.display.set_mode((size, size))
        self.clock = pygame.time.Clock()
        self.fps = fps

    def show(self, frame: np.ndarray) -> None:
        pg = self._pygame
        surf = pg.surfarray.make_surface(np.ascontiguousarray(frame.swapaxes(0, 1)))
        self.screen.blit(surf, (0, 0))
        pg.event.pump()
        pg.display.flip()
        self.clock.tick(self.fps)

    def close(self) -> None:
        self._pygame.display.quit()
