"""The simulation: the pymunk world, what its robot senses and the limits of that sensing.

:mod:`~lfmdr_gym.sim.world` (the arena, its layouts and checked moves),
:mod:`~lfmdr_gym.sim.sensors` (pure geometry of a pose and the objects),
:mod:`~lfmdr_gym.sim.sensing_limits` (field of view, range, noise, dropouts, occlusion),
:mod:`~lfmdr_gym.sim.kernels` (their compiled per-step loops), :mod:`~lfmdr_gym.sim.grid` (cell
grids: the objects near a pose, separated layouts), :mod:`~lfmdr_gym.sim.camera` (the MRCLAM
camera's keywords), and for the 3-D world :mod:`~lfmdr_gym.sim.tags3d` (tags on posts and walls,
anchors) and :mod:`~lfmdr_gym.sim.view3d` (a pitched camera's rays, view and occlusion).
"""

from lfmdr_gym.sim.camera import CAMERA_PRESET
from lfmdr_gym.sim.sensing_limits import SensingLimits
from lfmdr_gym.sim.world import Layout, World

__all__ = ["CAMERA_PRESET", "Layout", "SensingLimits", "World"]
