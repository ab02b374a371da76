"""The Gymnasium environment: a robot wandering among identifiable objects (paper §4.1)."""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from gymnasium import spaces

from lfmdr_gym.checks import check_real
from lfmdr_gym.render import draw_frame
from lfmdr_gym.sim import sensors
from lfmdr_gym.sim.grid import CellGrid
from lfmdr_gym.sim.sensing_limits import SensingLimits
from lfmdr_gym.sim.world import World
from lfmdr_gym.world_env import WorldEnv
from mappers.core.sensors import SENSORS, check_sensor, sensors_of

__all__ = ["LFMDREnv", "OBSERVATION_TYPES", "observation_factory"]


# ----------------------------------------------------------------------------- observation types
class VisibilityObservation:
    """``"visibility"``: MultiBinary(M), 1 where the object is seen (visual angle and occlusion)."""

    key = "visibility"

    def __init__(self, env: LFMDREnv) -> None:
        self.radius = env.world.object_radius
        self.visual_angle = math.radians(env.visual_angle_deg)
        self.occlusion = env.occlusion
        self.n_objects = env.world.n_objects
        # Targets lie within d_vis; their occluders within sqrt(d_vis^2 + r^2) (see sensors).
        d_vis = sensors.visibility_distance(self.radius, self.visual_angle)
        self.reach = math.hypot(d_vis, self.radius)
        self.d_vis2 = d_vis * d_vis
        self.space = spaces.MultiBinary(env.world.n_objects)
        self.local = True  # reads only the objects within `reach`: the env may use a cell grid

    def observe(self, rel, d2, heading, cand, rc, dc2, q) -> np.ndarray:
        return sensors.visibility_kernel(self.n_objects, cand, rc, dc2, self.d_vis2, q, self.occlusion)


class BearingObservation:
    """``"bearing"``: Box(-1, 1, (M, 2)), ``[cos, sin]`` of each bearing from the heading, CCW positive."""

    key = "bearing"
    reach = 0.0  # needs every object, not a nearby subset
    local = False

    def __init__(self, env: LFMDREnv) -> None:
        self.space = spaces.Box(-1.0, 1.0, (env.world.n_objects, 2), np.float32)

    def observe(self, rel, d2, heading, cand, rc, dc2, q) -> np.ndarray:
        return sensors.bearing_from_rel(rel, d2, heading, np.float32)


class RangeObservation:
    """``"range"``: Box(0, high, (M,)), centre-to-centre distance; 0 beyond ``max_range``.

    ``high`` is ``max_range``, or without one the arena's diagonal (no two points inside are
    farther apart): a finite bound, as Gymnasium's checker asks.
    """

    key = "range"
    reach = 0.0  # needs every object, not a nearby subset
    local = False

    def __init__(self, env: LFMDREnv) -> None:
        self.max_range = env.max_range
        high = env.max_range if env.max_range is not None else env.world.arena_size * math.sqrt(2.0)
        self.high = high + 10.0 * env.range_noise  # room for noise (see SensingLimits)
        self.space = spaces.Box(0.0, self.high, (env.world.n_objects,), np.float32)

    def observe(self, rel, d2, heading, cand, rc, dc2, q) -> np.ndarray:
        return sensors.ranges_from_rel(d2, self.max_range, np.float32)


OBSERVATION_TYPES = {
    "visibility": VisibilityObservation,
    "bearing": BearingObservation,
    "range": RangeObservation,
}


assert tuple(OBSERVATION_TYPES) == SENSORS  # one observation type per sensor of the vocabulary


def observation_factory(env: LFMDREnv, sensor: str):
    """The observation type named ``sensor`` for ``env`` (as HighwayEnv's ``observation_factory``)."""
    return OBSERVATION_TYPES[check_sensor(sensor)](env)


# ----------------------------------------------------------------------------- the environment
class LFMDREnv(WorldEnv):
    """
    ## Description

    The world of Yairi (ICML 2007), "Map Building without Localization by Dimensionality
    Reduction Techniques": a disc robot wanders in a square arena (side 2.5 m, centred on the
    origin) among ``n_objects`` identifiable static cylinders (48 mm diameter) laid out at random
    with clearances. Each step it turns by the action, advances ``step_length`` (0.2 m) along its
    new heading and observes every object with its mapping sensor. The world is simulated in
    pymunk; a move that would hit an object or a wall stops just short of the contact, so no
    policy can take the robot through one. The sensor histories are what a map is built from;
    the ground truth in ``info`` is for scoring only.

    ## Observation Space

    A ``Dict`` with the mapping sensor (chosen by ``sensor``) and a proximity ring:

    - ``"visibility"``: ``MultiBinary(M)`` (int8). Object j is visible iff its horizontal visual
      angle ``2 asin(r / d_j)`` exceeds ``visual_angle_deg`` (d below 0.550 m by default) and, with
      ``occlusion``, the segment from the robot's centre to the object's centre passes no nearer
      than r to another object's centre (see :func:`lfmdr_gym.sim.sensors.visibility`).
    - ``"bearing"``: ``Box(-1, 1, (M, 2), float32)``: ``[cos theta, sin theta]`` of each object's
      bearing relative to the heading, counter-clockwise positive (left is ``sin > 0``).
    - ``"range"``: ``Box(0, high, (M,), float32)``: distance from the robot's centre to each
      object's centre; with ``max_range`` an object farther away is not sensed and reads 0.
      ``high`` is ``max_range``, or the arena's diagonal without one (plus ``10 * range_noise``).
    - ``"proximity"``: ``Box(0, proximity_range, (n_proximity_rays,), float32)``: ray k points at
      ``heading + 2 pi k / n_proximity_rays`` (CCW, ray 0 straight ahead); its value is the
      distance from the robot's centre to the first obstacle (object surface or wall), capped at
      ``proximity_range``. It lets a policy avoid obstacles from the observation alone: a
      reading below ``step_length + robot_radius`` on the ray a move follows means that move
      hits something. Rays are thin and the robot is not, so an object lying between rays can
      still block a move; the physics then stops the robot short (``info["blocked"]``).
    - ``"observed"`` (only with a sensing limit on, see *Imperfect sensing*): ``MultiBinary(M)``
      (int8), 1 for the objects the mapping sensor reported on this step.

    Fused sensing (``sensor="range-bearing"`` or ``"visibility-bearing"``, the ids
    ``LFMDR-RangeBearing-v0``, ``LFMDR-VisibilityBearing-v0`` and ``LFMDR-Camera-v0``): the
    observation holds every sensor of the set, each as above, read from the same pose after the
    same move; one ``"observed"`` serves them all (one camera: the field of view, range and line
    of sight decide for every sensor of the set), while each sensor's noise or dropouts are its
    own, drawn independently. ``collect`` records such an env into a fused History.

    ## Imperfect sensing

    All off by default (the paper's perfect sensors); see
    :class:`lfmdr_gym.sim.sensing_limits.SensingLimits`. ``fov_deg`` (field of view centred on the
    heading, in (0, 360]) and ``max_range`` (centre to centre) limit every sensor;
    ``bearing_noise_deg`` (Gaussian, std of the bearing angle), ``range_noise`` (Gaussian, std in
    metres), ``miss_rate`` / ``false_rate`` (a visible object reported not visible / an invisible
    one reported visible, each entry independently, rates in [0, 1)) and ``line_of_sight``
    (occlusion for bearing and range: an object hidden behind another is not measured; visibility
    has its own ``occlusion``) apply to their sensor only. With any of them on, the observation
    gains ``"observed"``; entries not observed read 0. For visibility, ``observed`` marks where the
    camera looked (inside the view and range), not what it saw. Noise and dropouts are drawn from a
    generator seeded from the reset seed, apart from ``np_random``: the same seed and actions give
    the same trajectory with or without them.

    ## Action Space

    ``Box(-max_turn, max_turn, (1,), float32)``: the heading change [rad] before the move
    (``max_turn = pi/4`` by default). Values outside are clipped; NaN raises ``ValueError``.

    ## Rewards and episode end

    Mapping has no reward: every step returns 0.0 and ``terminated=False``. Episodes end by
    truncation only (``max_episode_steps=2000`` in the registered ids).

    ## Info

    At reset and after every step (fresh arrays each time): ``"robot_pose"`` (3,) float64
    ``(x, y, heading)`` with heading in (-pi, pi]; ``"object_positions"`` (M, 2);
    ``"anchor_ids"`` (A,) int64; ``"anchor_positions"`` (A, 2); ``"blocked"``: whether the last
    move was stopped by an obstacle.

    ## Starting State

    ``reset(seed=...)`` draws a new layout, anchors and start pose from ``np_random`` and
    rebuilds the pymunk world: the same seed and actions give bit-identical observations.
    ``options`` may fix parts of the episode: ``{"object_positions": (M, 2), "anchor_ids": (A,),
    "robot_pose": (3,)}`` (validated; user layouts need no clearances, only no overlaps).

    ## Arguments

    ```python
    gymnasium.make("LFMDR-Visibility-v0")   # or LFMDR-Bearing-v0, LFMDR-Range-v0,
    # LFMDR-RangeBearing-v0, LFMDR-VisibilityBearing-v0, LFMDR-Camera-v0 (the range-bearing
    # env with the MRCLAM camera's keywords, lfmdr_gym.sim.camera.CAMERA_PRESET)
    LFMDREnv(sensor="visibility", n_objects=50, arena_size=2.5, object_diameter=0.048,
             robot_radius=0.05, step_length=0.2, max_turn=pi/4, visual_angle_deg=5.0,
             occlusion=True, anchors="corners", n_anchors=4, object_clearance=0.15,
             wall_clearance=0.15, n_proximity_rays=32, proximity_range=0.5, max_range=None,
             fov_deg=360.0, bearing_noise_deg=0.0, range_noise=0.0, miss_rate=0.0,
             false_rate=0.0, line_of_sight=False, render_mode=None)
    ```

    ``sensor``: ``"visibility"``, ``"bearing"``, ``"range"``, or a fused set: ``"range-bearing"``,
    ``"visibility-bearing"`` (a sensing limit is accepted when it applies to a sensor of the set).
    Lengths in metres. ``object_clearance``/``wall_clearance``: least gap between two objects'
    surfaces / between an object and a wall in random layouts. ``anchors``: ``"corners"`` (the
    objects nearest ``n_anchors`` points spread along the walls from a corner; the four corners
    by default), ``"grid"`` (the objects nearest a lattice of ``n_anchors`` points spread over
    the arena) or ``"random"``; ``n_anchors >= 3``. For a larger world at the same object
    density, scale ``arena_size`` with ``sqrt(n_objects / 50)``: with the visibility sensor and
    no sensing limits a step costs the same at any ``n_objects`` (only nearby objects are
    touched). ``visual_angle_deg`` and ``occlusion`` shape the visibility sensor (the others
    ignore them); the sensing limits are above. Every
    argument is checked on construction (``ValueError`` naming it).

    ## Version History

    - v0: initial version; the imperfect-sensing keywords came later, off by default (the
      observations without them are unchanged); the fused sensors (range-bearing,
      visibility-bearing) and the camera preset later still, as new ids.
    """

    def __init__(
        self,
        sensor: str = "visibility",
        *,
        n_objects: int = 50,
        arena_size: float = 2.5,
        object_diameter: float = 0.048,
        robot_radius: float = 0.05,
        step_length: float = 0.2,
        max_turn: float = math.pi / 4,
        visual_angle_deg: float = 5.0,
        occlusion: bool = True,
        anchors: str = "corners",
        n_anchors: int = 4,
        object_clearance: float = 0.15,
        wall_clearance: float = 0.15,
        n_proximity_rays: int = 32,
        proximity_range: float = 0.5,
        max_range: float | None = None,
        fov_deg: float = 360.0,
        bearing_noise_deg: float = 0.0,
        range_noise: float = 0.0,
        miss_rate: float = 0.0,
        false_rate: float = 0.0,
        line_of_sight: bool = False,
        render_mode: str | None = None,
    ) -> None:
        names = sensors_of(sensor)
        self.world = World(
            n_objects=n_objects,
            arena_size=arena_size,
            object_diameter=object_diameter,
            robot_radius=robot_radius,
            object_clearance=object_clearance,
            wall_clearance=wall_clearance,
            anchors=anchors,
            n_anchors=n_anchors,
        )
        self.sensor = sensor
        self._set_motion(step_length, max_turn)
        self.visual_angle_deg = check_real(
            "visual_angle_deg", visual_angle_deg, low=0.0, low_open=True, high=180.0, high_open=True
        )
        if not isinstance(occlusion, bool | np.bool_):
            raise ValueError(f"occlusion must be True or False, got {occlusion!r}")
        self.occlusion = bool(occlusion)
        self._set_proximity(n_proximity_rays, proximity_range)
        self.max_range = (
            None if max_range is None else check_real("max_range", max_range, low=0.0, low_open=True)
        )
        limits = dict(fov_deg=fov_deg, max_range=self.max_range, bearing_noise_deg=bearing_noise_deg,
                      range_noise=range_noise, miss_rate=miss_rate, false_rate=false_rate,
                      line_of_sight=line_of_sight)
        self.range_noise = check_real("range_noise", range_noise, low=0.0)
        self._set_render_mode(render_mode)

        self._set_up_sensing(names, limits)
        self._anchor_positions = np.zeros((0, 2))
        self._grid: CellGrid | None = None

    def _set_up_sensing(self, names: tuple[str, ...], limits: dict) -> None:
        """The observation types of the sensors ``names``, the imperfect-sensing limits, the
        proximity rays, the candidate prefilter's reach and the spaces."""
        # One observation type per sensor (several for a fused set, read from the same pose).
        self.sensors = names
        self._obs_types = {s: observation_factory(self, s) for s in names}
        self._fused = len(names) > 1
        # The sensor drawn by render(): a fused set's other than bearing (whose rays go to every
        # object), i.e. range or visibility.
        self._key = names[0] if not self._fused else next(s for s in names if s != "bearing")
        self._obs_type = self._obs_types[self._key]
        range_type = self._obs_types.get("range")
        # Imperfect sensing (lfmdr_gym.sim.sensing_limits): built only when a limit is on.
        self._limits = (SensingLimits(self.sensor, self.world.n_objects, self.world.object_radius,
                                      range_high=getattr(range_type or self._obs_type, "high", 1.0),
                                      **limits)
                        if SensingLimits.active(limits) else None)
        # One candidate prefilter serves the proximity ring and a nearby-only sensor.
        self._reach = max(self.proximity_range + self.world.object_radius,
                          *(t.reach for t in self._obs_types.values()))
        self._reach2 = self._reach * self._reach
        self._r2 = self.world.object_radius * self.world.object_radius
        self._xy = np.zeros(2)  # the robot's (x, y), reused every step
        self.observation_space = spaces.Dict(
            {
                **{key: t.space for key, t in self._obs_types.items()},
                "proximity": spaces.Box(
                    0.0, self.proximity_range, (self.n_proximity_rays,), np.float32
                ),
                **({"observed": spaces.MultiBinary(self.world.n_objects)} if self._limits else {}),
            }
        )

    # ------------------------------------------------------------------ core API
    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
        super().reset(seed=seed)
        if self._limits is not None:
            self._limits.reset(seed)
        layout = self.world.layout(self.np_random, options)
        self.world.build(layout)
        # A nearby-only sensor touches only the objects in the robot's 3 x 3 block of grid cells,
        # so a step costs the same at any M; readings are bit-identical to a scan of all objects.
        # (The sensing limits read every object's offset, so they keep the full scan.)
        self._grid = (CellGrid(layout.object_positions, self.world.arena_half, self._reach)
                      if all(t.local for t in self._obs_types.values()) and self._limits is None
                      else None)
        self._anchor_positions = layout.object_positions[layout.anchor_ids]
        return self._first_observation()

    def _observe(self) -> dict[str, np.ndarray]:
        # The hot path: a handful of numpy calls on arrays of ~50 rows, where each call's fixed
        # overhead (about a microsecond) outweighs its arithmetic. Every value is computed by the
        # same floating-point operations as the plain formulas, so observations are bit-identical.
        w = self.world
        x, y, h = w.x, w.y, w.heading
        xy = self._xy
        xy[0] = x
        xy[1] = y
        if self._grid is None:
            rel = w.object_positions - xy
            sq = rel * rel
            d2 = sq[:, 0] + sq[:, 1]  # == einsum("ij,ij->i", rel, rel), at half its overhead
            cand = (d2 < self._reach2).nonzero()[0]
            rc, dc2 = rel.take(cand, axis=0), d2.take(cand)  # take: as rel[cand], cheaper
        else:  # the same rows, in the same (ascending) order, from the nearby block alone
            near, points = self._grid.near_points(x, y)
            rel = points - xy
            sq = rel * rel
            d2 = sq[:, 0] + sq[:, 1]
            sel = (d2 < self._reach2).nonzero()[0]
            cand, rc, dc2 = near.take(sel), rel.take(sel, axis=0), d2.take(sel)
        q = dc2 - self._r2  # d^2 - r^2, shared by the proximity ring and visibility
        prox = sensors.proximity_kernel(
            x, y, h, rc, q, w.arena_half, self._dirs, self.proximity_range
        )
        readings = {k: t.observe(rel, d2, h, cand, rc, dc2, q) for k, t in self._obs_types.items()}
        obs = {**readings, "proximity": prox.astype(np.float32)}
        if self._limits is not None:
            limited, obs["observed"] = self._limits.apply(readings, rel, d2, h)
            obs.update(limited)
        return obs

    def _info(self, blocked: bool) -> dict[str, Any]:
        w = self.world
        return self._world_info(blocked, w.object_positions, w.anchor_ids, self._anchor_positions)

    # ------------------------------------------------------------------ rendering
    def _frame(self) -> np.ndarray:
        """The frame :meth:`render` shows: the arena, the objects coloured by the drawn sensor's
        reading, the robot and its proximity ring (:func:`lfmdr_gym.render.draw_frame`)."""
        w = self.world
        obs = self._last_obs or {}
        return draw_frame(
            arena_half=w.arena_half,
            object_positions=w.object_positions,
            object_radius=w.object_radius,
            robot_pose=w.pose,
            robot_radius=w.robot_radius,
            anchor_ids=w.anchor_ids,
            sensor=self._key,
            reading=obs.get(self._key),
            proximity=obs.get("proximity"),
            observed=obs.get("observed"),
        )
