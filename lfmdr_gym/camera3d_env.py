"""``LFMDR-Camera3D-v0``: a pitched camera on the planar robot, mapping tags at heights in 3-D (issue 34)."""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from gymnasium import spaces

from lfmdr_gym.checks import check_int, check_real
from lfmdr_gym.render import draw_frame
from lfmdr_gym.sim import sensors, tags3d, view3d
from lfmdr_gym.sim.world import Layout, World
from lfmdr_gym.world_env import WorldEnv
from mappers.core.sensors import sensors_of

__all__ = ["CAMERA3D_SENSORS", "Camera3DEnv"]

CAMERA3D_SENSORS = ("visibility", "bearing", "range", "range-bearing")
"""The sensors (and the fused set) the 3-D camera env observes."""

RESET_OPTIONS = ("post_positions", "tag_positions", "anchor_ids", "robot_pose")

WALL_TAG_CORNER_MARGIN = 0.1
"""Least distance [m] of a random wall tag from a corner of the arena."""

_STREAM_TAG = 0x63336400  # mixed into the reset seed: the noise stream is apart from np_random


class Camera3DEnv(WorldEnv):
    """
    ## Description

    The planar world of :class:`lfmdr_gym.env.LFMDREnv` (a disc robot wandering in a square
    pymunk arena, side ``arena_size``, among ``n_posts`` static cylinders: the *posts*) with the
    objects to map lifted into 3-D: *tags* at heights in ``tag_heights`` (0-2 m by default),
    ``tags_per_post`` on every post and ``n_wall_tags`` on the walls
    (:mod:`lfmdr_gym.sim.tags3d`). A camera on the robot, ``camera_height`` above the floor and
    pitched up by ``pitch_deg``, with a horizontal and a vertical field of view and a range
    limit, reads the tags in view; posts hide the tags behind them
    (:mod:`lfmdr_gym.sim.view3d` gives the geometry and the occlusion model). Each step the
    robot turns by the action and advances ``step_length`` along its heading (moves stop short of
    any contact, as in the planar envs). There is no odometry: a map is built from the readings
    alone; the ground truth in ``info`` is for scoring.

    ## Observation Space

    A ``Dict`` with the sensor's entries (``sensor``), the proximity ring and, for bearing and
    range, ``"observed"``:

    - ``"bearing"``: ``Box(-1, 1, (M, 3), float32)``, the unit ray to each tag in the camera's
      frame (``z`` forward, ``x`` right, ``y`` down); ``(0, 0, 0)`` for a tag not read.
    - ``"range"``: ``Box(0, high, (M,), float32)``, the 3-D distance from the camera's centre
      [m]; 0 for a tag not read. ``high`` is ``max_range`` (or the arena's 3-D diagonal) plus
      ten standard deviations of ``range_noise``.
    - ``"visibility"``: ``MultiBinary(M)`` (int8), 1 for the tags read this step. A 0 is a
      reading (not seen), so visibility has no ``observed``.
    - ``"observed"``: ``MultiBinary(M)``, 1 for the tags read (in view and range, not hidden, not
      missed); a bearing or range history's mask.
    - ``"proximity"``: ``Box(0, proximity_range, (n_proximity_rays,), float32)``, the ring of
      :func:`lfmdr_gym.sim.sensors.proximity` against the posts and walls, for obstacle avoidance.

    ## Sensing keywords

    ``bearing_noise_deg``: each ray is turned by Gaussian noise of this standard deviation in each
    of its two angular components (the ray plus a Gaussian vector perpendicular to it, normalised).
    ``range_noise``: Gaussian noise [m] on each range (a negative result reflected at 0: a
    range is a distance). ``miss_rate``: the
    probability that a tag that could be read is not (a dropped detection: no ray, no range, a 0
    in visibility). ``occlusion``: posts hide tags. Noise and dropouts come from a generator
    seeded from the reset seed, apart from ``np_random``: the same seed and actions give the same
    layout and path with or without them.

    ## Action Space, rewards, episode end

    As the planar envs: ``Box(-max_turn, max_turn, (1,), float32)``, reward 0, truncation only
    (``max_episode_steps=2000`` in the registered id).

    ## Info

    ``"robot_pose"`` (3,) ``(x, y, heading)``; ``"object_positions"`` (M, 3) the tags;
    ``"anchor_ids"`` (A,); ``"anchor_positions"`` (A, 3); ``"post_positions"`` (K, 2);
    ``"blocked"``. Fresh arrays every call.

    ## Starting State

    ``reset(seed=...)`` draws the posts, the tags and the start pose from ``np_random``; the
    anchors are the lowest tag and then ``n_anchors - 1`` tags in farthest-point order
    (:func:`lfmdr_gym.sim.tags3d.choose_anchors`). ``options`` may fix ``"post_positions"`` (K,
    2), ``"tag_positions"`` (M, 3: a tag on a post's axis is mounted on it, any other must lie
    inside the walls and outside the posts), ``"anchor_ids"`` (>= 4, not on one plane) and
    ``"robot_pose"``.

    ## Arguments

    ```python
    gymnasium.make("LFMDR-Camera3D-v0")
    Camera3DEnv(sensor="range-bearing", n_posts=15, tags_per_post=2, n_wall_tags=20,
                tag_heights=(0.0, 2.0), arena_size=2.5, post_diameter=0.048,
                post_clearance=0.15, wall_clearance=0.15, robot_radius=0.05, step_length=0.2,
                max_turn=pi/4, camera_height=0.3, pitch_deg=20.0, hfov_deg=90.0,
                vfov_deg=70.0, max_range=3.0, occlusion=True, bearing_noise_deg=0.0,
                range_noise=0.0, miss_rate=0.0, n_anchors=6, n_proximity_rays=32,
                proximity_range=0.5, render_mode=None)
    ```

    ``sensor``: ``"visibility"``, ``"bearing"``, ``"range"`` or ``"range-bearing"``. Lengths in
    metres, angles in degrees. Every argument is checked on construction (ValueError naming it).

    ## Version History

    - v0: initial version (issue 34).
    """

    def __init__(
        self,
        sensor: str = "range-bearing",
        *,
        n_posts: int = 15,
        tags_per_post: int = 2,
        n_wall_tags: int = 20,
        tag_heights: tuple[float, float] = (0.0, 2.0),
        arena_size: float = 2.5,
        post_diameter: float = 0.048,
        post_clearance: float = 0.15,
        wall_clearance: float = 0.15,
        robot_radius: float = 0.05,
        step_length: float = 0.2,
        max_turn: float = math.pi / 4,
        camera_height: float = 0.3,
        pitch_deg: float = 20.0,
        hfov_deg: float = 90.0,
        vfov_deg: float = 70.0,
        max_range: float | None = 3.0,
        occlusion: bool = True,
        bearing_noise_deg: float = 0.0,
        range_noise: float = 0.0,
        miss_rate: float = 0.0,
        n_anchors: int = 6,
        n_proximity_rays: int = 32,
        proximity_range: float = 0.5,
        render_mode: str | None = None,
    ) -> None:
        if sensor not in CAMERA3D_SENSORS:
            raise ValueError(f"sensor must be one of {list(CAMERA3D_SENSORS)} for the 3-D camera, "
                             f"got {sensor!r}")
        self.sensor = sensor
        self.sensors = sensors_of(sensor)
        self.world = World(n_objects=n_posts, arena_size=arena_size, object_diameter=post_diameter,
                           robot_radius=robot_radius, object_clearance=post_clearance,
                           wall_clearance=wall_clearance, anchors="random", n_anchors=3)
        self.tags_per_post = check_int("tags_per_post", tags_per_post, low=0)
        self.n_wall_tags = check_int("n_wall_tags", n_wall_tags, low=0)
        self.n_tags = self.world.n_objects * self.tags_per_post + self.n_wall_tags
        self.n_anchors = check_int("n_anchors", n_anchors, low=4)
        if self.n_anchors > self.n_tags:
            raise ValueError(f"n_anchors={n_anchors} exceeds the {self.n_tags} tags "
                             f"(n_posts * tags_per_post + n_wall_tags)")
        self.tag_heights = tags3d.check_heights(tag_heights)
        if self.world.arena_half <= WALL_TAG_CORNER_MARGIN and self.n_wall_tags:
            raise ValueError(f"arena_size={arena_size} leaves no wall away from the corners for tags")
        self._set_motion(step_length, max_turn)
        self.camera = view3d.CameraModel(height=check_real("camera_height", camera_height),
                                         pitch_deg=pitch_deg, hfov_deg=hfov_deg, vfov_deg=vfov_deg,
                                         max_range=max_range, occlusion=occlusion)
        self.max_range = self.camera.max_range
        self.bearing_noise = math.radians(check_real("bearing_noise_deg", bearing_noise_deg, low=0.0))
        self.range_noise = check_real("range_noise", range_noise, low=0.0)
        self.miss_rate = check_real("miss_rate", miss_rate, low=0.0, high=1.0, high_open=True)
        for name, value, needs in (("bearing_noise_deg", bearing_noise_deg, "bearing"),
                                   ("range_noise", range_noise, "range")):
            if value and needs not in self.sensors:
                raise ValueError(f"{name} applies to the {needs} sensor, not to {sensor!r}")
        self._set_proximity(n_proximity_rays, proximity_range)
        self._set_render_mode(render_mode)

        self.observation_space = self._observation_space()
        self._tags = np.zeros((0, 3))
        self._hosts = np.zeros(0, dtype=np.int64)
        self._anchor_ids = np.zeros(0, dtype=np.int64)
        self._noise: np.random.Generator | None = None

    def _observation_space(self) -> spaces.Dict:
        """The observation space: each sensor's readings of the tags (and which were observed,
        for the masked sensors), the proximity ring; sets ``range_high``, the largest range
        a reading can take (the camera's reach plus ten noise deviations), and ``_masked``."""
        a = self.world.arena_half
        reach = self.camera.max_range
        if reach is None:
            reach = math.sqrt(8.0 * a * a + max(self.tag_heights[1], self.camera.height) ** 2)
        self.range_high = reach + 10.0 * self.range_noise
        m = self.n_tags
        entries: dict[str, spaces.Space] = {}
        if "visibility" in self.sensors:
            entries["visibility"] = spaces.MultiBinary(m)
        if "bearing" in self.sensors:
            entries["bearing"] = spaces.Box(-1.0, 1.0, (m, 3), np.float32)
        if "range" in self.sensors:
            entries["range"] = spaces.Box(0.0, self.range_high, (m,), np.float32)
        entries["proximity"] = spaces.Box(0.0, self.proximity_range, (self.n_proximity_rays,),
                                          np.float32)
        self._masked = self.sensor != "visibility"
        if self._masked:
            entries["observed"] = spaces.MultiBinary(m)
        return spaces.Dict(entries)

    # ------------------------------------------------------------------ episodes
    def reset(self, *, seed: int | None = None,
              options: dict[str, Any] | None = None) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
        super().reset(seed=seed)
        if seed is not None:
            self._noise = np.random.default_rng(np.random.SeedSequence([int(seed), _STREAM_TAG]))
        elif self._noise is None:
            self._noise = np.random.default_rng()
        options = {} if options is None else options
        if not isinstance(options, dict):
            raise ValueError(f"options must be a dict, got {type(options).__name__}")
        unknown = sorted(set(options) - set(RESET_OPTIONS))
        if unknown:
            raise ValueError(f"unknown reset option(s) {unknown}; allowed: {list(RESET_OPTIONS)}")
        w, rng = self.world, self.np_random
        posts = options.get("post_positions")
        posts = w.sample_objects(rng) if posts is None else w.check_objects(posts)
        tags = options.get("tag_positions")
        if tags is None:
            tags, hosts = tags3d.place_tags(rng, posts, w.arena_half, tags_per_post=self.tags_per_post,
                                            n_wall_tags=self.n_wall_tags, heights=self.tag_heights,
                                            corner_margin=WALL_TAG_CORNER_MARGIN)
        else:
            tags, hosts = tags3d.check_tags(tags, posts, w.object_radius, w.arena_half)
            if tags.shape[0] != self.n_tags:
                raise ValueError(f"tag_positions must have {self.n_tags} rows (the env's "
                                 f"observation space), got {tags.shape[0]}")
        ids = options.get("anchor_ids")
        ids = (tags3d.choose_anchors(tags, self.n_anchors) if ids is None
               else tags3d.check_anchor_ids(ids, tags))
        pose = options.get("robot_pose")
        pose = w.sample_pose(posts, rng) if pose is None else w.check_pose(pose, posts)
        for arr in (posts, tags, hosts, ids):
            arr.setflags(write=False)
        w.build(Layout(posts, np.zeros(0, dtype=np.int64), pose))
        self._tags, self._hosts, self._anchor_ids = tags, hosts, ids
        return self._first_observation()

    def _observe(self) -> dict[str, np.ndarray]:
        w = self.world
        pose = w.pose
        rays, dist, seen = view3d.view(pose, self._tags, self._hosts, w.object_positions,
                                       w.object_radius, self.camera)
        m, rng = self.n_tags, self._noise
        # Draws in a fixed order and for every tag, whatever is seen, so the stream stays aligned.
        if self.miss_rate > 0.0:
            seen &= rng.random(m) >= self.miss_rate
        obs: dict[str, np.ndarray] = {}
        if "visibility" in self.sensors:
            obs["visibility"] = seen.astype(np.int8)
        if "bearing" in self.sensors:
            if self.bearing_noise > 0.0:
                e = rng.normal(0.0, self.bearing_noise, (m, 3))
                e -= np.einsum("ij,ij->i", e, rays)[:, None] * rays  # perpendicular to the ray
                rays = rays + e
                rays /= np.linalg.norm(rays, axis=1, keepdims=True)
            obs["bearing"] = np.where(seen[:, None], rays, 0.0).astype(np.float32)
        if "range" in self.sensors:
            if self.range_noise > 0.0:
                # reflected at 0 (a distance; a mapper refuses an observed range <= 0), and
                # within the space (10 sd past the range limit: never reached in practice)
                dist = np.minimum(np.abs(dist + rng.normal(0.0, self.range_noise, m)),
                                  self.range_high)
            obs["range"] = np.where(seen, dist, 0.0).astype(np.float32)
        rel = w.object_positions - pose[:2]
        q = np.einsum("ij,ij->i", rel, rel) - w.object_radius ** 2
        obs["proximity"] = sensors.proximity_kernel(
            pose[0], pose[1], pose[2], rel, q, w.arena_half, self._dirs, self.proximity_range
        ).astype(np.float32)
        if self._masked:
            obs["observed"] = seen.astype(np.int8)
        return obs

    def _info(self, blocked: bool) -> dict[str, Any]:
        return self._world_info(bool(blocked), self._tags, self._anchor_ids,
                                self._tags[self._anchor_ids],
                                post_positions=self.world.object_positions)

    # ------------------------------------------------------------------ rendering
    def _frame(self) -> np.ndarray:
        """A top view: the tags at their floor positions, those read this step in green
        (:func:`lfmdr_gym.render.draw_frame`)."""
        w = self.world
        obs = self._last_obs or {}
        seen = obs.get("observed", obs.get("visibility"))
        return draw_frame(arena_half=w.arena_half, object_positions=self._tags[:, :2],
                          object_radius=w.object_radius, robot_pose=w.pose,
                          robot_radius=w.robot_radius, anchor_ids=self._anchor_ids,
                          sensor="visibility", reading=seen, proximity=obs.get("proximity"))
