"""What every env over the planar robot world (:class:`lfmdr_gym.sim.world.World`) does the same
way: checking the render mode, a step (turn, move, observe), rendering a frame and closing the
window.

:class:`lfmdr_gym.env.LFMDREnv` and :class:`lfmdr_gym.camera3d_env.Camera3DEnv` differ in what
the robot senses and how a frame is drawn, not in how the robot moves or how the frame is shown;
they subclass :class:`WorldEnv` and give ``_observe``, ``_info`` and ``_frame``.
"""

from __future__ import annotations

import math
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from lfmdr_gym.checks import check_int, check_real
from lfmdr_gym.render import HumanViewer, available_render_modes, human_rendering_error
from lfmdr_gym.sim import sensors
from lfmdr_gym.sim.world import World, action_turn

__all__ = ["WorldEnv"]


class WorldEnv(gym.Env):
    """A Gymnasium env whose robot moves in a :class:`~lfmdr_gym.sim.world.World`: each step it
    turns by the action (at most ``max_turn``, :func:`~lfmdr_gym.sim.world.action_turn`) and
    advances ``step_length``, stopping short of any contact; there is no reward and no end.

    A subclass sets ``world`` and calls :meth:`_set_motion`, :meth:`_set_proximity` and
    :meth:`_set_render_mode` in its ``__init__``, and gives ``_observe()`` (the observation at the current pose),
    ``_info(blocked)`` and ``_frame()`` (the RGB frame of the current state).
    """

    # "human" is offered only where it can work (pygame and a display), so that Gymnasium's
    # check_env, which renders every listed mode, passes on a headless machine.
    metadata = {"render_modes": available_render_modes(), "render_fps": 10}

    world: World
    max_turn: float
    step_length: float

    def _set_motion(self, step_length: float, max_turn: float) -> None:
        """Check and keep the move of a step: ``step_length`` > 0 [m], ``0 < max_turn <= pi``
        [rad] (the action space is ``Box(-max_turn, max_turn, (1,))``)."""
        self.step_length = check_real("step_length", step_length, low=0.0, low_open=True)
        self.max_turn = check_real("max_turn", max_turn, low=0.0, low_open=True, high=math.pi)
        self.action_space = spaces.Box(-self.max_turn, self.max_turn, (1,), np.float32)

    def _set_proximity(self, n_proximity_rays: int, proximity_range: float) -> None:
        """Check and keep the proximity ring: ``n_proximity_rays`` >= 1 rays (their directions
        in ``_dirs``), each reading up to ``proximity_range`` > 0 [m]."""
        self.n_proximity_rays = check_int("n_proximity_rays", n_proximity_rays, low=1)
        self.proximity_range = check_real("proximity_range", proximity_range, low=0.0, low_open=True)
        self._dirs = sensors.ray_directions(self.n_proximity_rays)

    def _set_render_mode(self, render_mode: str | None) -> None:
        """Check ``render_mode`` (``None`` or one of ``metadata["render_modes"]``; ``"human"``
        raises the reason it cannot work here) and keep it, with no window open yet."""
        if render_mode == "human" and human_rendering_error() is not None:
            raise human_rendering_error()
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise ValueError(f"render_mode must be one of {self.metadata['render_modes']} or None, "
                             f"got {render_mode!r}")
        self.render_mode = render_mode
        self._last_obs: dict[str, np.ndarray] | None = None
        self._viewer: HumanViewer | None = None

    def _sense(self) -> dict[str, np.ndarray]:
        """The observation at the current pose, kept for :meth:`render`."""
        self._last_obs = self._observe()
        return self._last_obs

    def _world_info(self, blocked: bool, object_positions: np.ndarray, anchor_ids: np.ndarray,
                    anchor_positions: np.ndarray, **extra: Any) -> dict[str, Any]:
        """``info``: the robot's pose, the objects' and anchors' ground truth (``extra`` entries
        after them) and whether the move was ``blocked``. Fresh arrays every call: a caller may
        keep or modify them (and check_env insists)."""
        return {
            "robot_pose": self.world.pose,
            "object_positions": object_positions.copy(),
            "anchor_ids": anchor_ids.copy(),
            "anchor_positions": anchor_positions.copy(),
            **{key: value.copy() for key, value in extra.items()},
            "blocked": blocked,
        }

    def _first_observation(self) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
        """The end of ``reset`` once the world is built: ``(observation, info)``, with the
        window updated in ``"human"`` mode."""
        obs = self._sense()
        if self.render_mode == "human":
            self.render()
        return obs, self._info(False)

    def step(self, action: Any) -> tuple[dict[str, np.ndarray], float, bool, bool, dict[str, Any]]:
        if not self.world.built:
            raise gym.error.ResetNeeded("call reset() before step()")
        turn = action_turn(action, self.max_turn)
        blocked = self.world.move(turn, self.step_length)
        obs = self._sense()
        if self.render_mode == "human":
            self.render()
        return obs, 0.0, False, False, self._info(blocked)

    def render(self) -> np.ndarray | None:
        """An RGB frame (``"rgb_array"``) or a window update (``"human"``); see
        :mod:`lfmdr_gym.render`."""
        if self.render_mode is None:
            gym.logger.warn("render() called without a render_mode; pass render_mode='rgb_array' "
                            "to gymnasium.make")
            return None
        if not self.world.built:
            raise gym.error.ResetNeeded("call reset() before render()")
        frame = self._frame()
        if self.render_mode == "rgb_array":
            return frame
        if self._viewer is None:
            self._viewer = HumanViewer(frame.shape[0], self.metadata["render_fps"])
        self._viewer.show(frame)
        return None

    def close(self) -> None:
        if self._viewer is not None:
            self._viewer.close()
            self._viewer = None
