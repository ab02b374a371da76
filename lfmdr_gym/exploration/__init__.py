"""Exploration policies: what drives the robot, seeing its observations only.

The contract a policy meets (:mod:`~lfmdr_gym.exploration.contract`), the paper's random walk
(:mod:`~lfmdr_gym.exploration.random_walk`) and the registry of named policies
(:mod:`~lfmdr_gym.exploration.registry`, :data:`POLICIES`). The other policies (``coverage``,
``spread``, ``even``, ``rl``) and what they perceive (the agent's view, scan matching, the walls
and the bumped cylinders in the robot's own frame) live in their own modules, imported when a
policy is asked for.
"""

from lfmdr_gym.exploration.contract import Policy, PredictPolicy, as_policy, base_env, check_policy
from lfmdr_gym.exploration.random_walk import RandomWalkPolicy
from lfmdr_gym.exploration.registry import POLICIES, PolicySpec

__all__ = [
    "Policy", "PredictPolicy", "as_policy", "base_env", "check_policy",
    "RandomWalkPolicy",
    "POLICIES", "PolicySpec",
]
