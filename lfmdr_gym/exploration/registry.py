"""The registered exploration policies: a name -> ``"module:Class"`` table, resolved on first use.

As Gymnasium's registry finds an env by its ``entry_point`` string, :data:`POLICIES` keeps
strings and imports a policy's module only when the policy is asked for; so this module imports
no policy, and no policy imports it (no import circle, and ``import lfmdr_gym`` does not pay for
the policies it does not use).
"""

from __future__ import annotations

import importlib
from collections.abc import Mapping
from dataclasses import dataclass, field
from types import MappingProxyType
from typing import Any

__all__ = ["POLICIES", "PolicySpec"]


@dataclass(frozen=True)
class PolicySpec:
    """One registered policy: ``entry_point`` names a class (``"package.module:Class"``) whose
    ``for_env(env, **kwargs)`` builds the policy for an env, and ``kwargs`` the keywords it is
    registered with (a caller's keywords override them).

    Calling the spec, ``spec(env, **kwargs)``, builds the policy: it is the factory of
    :data:`POLICIES`.
    """

    name: str
    entry_point: str
    kwargs: Mapping[str, Any] = field(default_factory=dict)

    def load(self) -> Any:
        """The policy class the entry point names (its module imported now, if not already)."""
        module, _, attr = self.entry_point.partition(":")
        return getattr(importlib.import_module(module), attr)

    def __call__(self, env: Any, **kwargs: Any) -> Any:
        return self.load().for_env(env, **{**self.kwargs, **kwargs})


_EXPLORATION = "lfmdr_gym.exploration"

POLICIES: Mapping[str, PolicySpec] = MappingProxyType({
    spec.name: spec for spec in (
        PolicySpec("random-walk", f"{_EXPLORATION}.random_walk:RandomWalkPolicy"),
        PolicySpec("coverage", f"{_EXPLORATION}.coverage:CoveragePolicy"),
        PolicySpec("coverage-scan", f"{_EXPLORATION}.coverage:CoveragePolicy",
                   MappingProxyType({"correct_drift": True})),
        PolicySpec("rl", f"{_EXPLORATION}.rl:MLPExplorationPolicy"),
        PolicySpec("spread", f"{_EXPLORATION}.spread:SpreadPolicy"),
        PolicySpec("even", f"{_EXPLORATION}.even:EvenPolicy"),
    )
})
"""Name -> factory ``factory(env, **kwargs) -> policy`` (a :class:`PolicySpec`): the exploration
policies ``lfmdr collect --policy NAME`` offers. A factory reads only the env's geometry (turn
limit, step length, robot and object radii, the room's size) and spaces; the policy then sees
observations only (:func:`~lfmdr_gym.exploration.contract.check_policy`).

- ``"random-walk"``: the paper's agent
  (:class:`lfmdr_gym.exploration.random_walk.RandomWalkPolicy`).
- ``"coverage"``: even coverage from a dead-reckoned visit memory
  (:class:`lfmdr_gym.exploration.coverage.CoveragePolicy`).
- ``"coverage-scan"``: the same with its dead reckoning corrected from the proximity rings
  (``correct_drift=True``, :mod:`lfmdr_gym.exploration.scan_match`).
- ``"rl"``: a PPO agent trained on the coverage reward, run in numpy from the shipped weights
  (:class:`lfmdr_gym.exploration.rl.MLPExplorationPolicy`; ``examples/train_rl_policy.py``).
- ``"spread"``: viewpoints spread evenly at the scale of the step (a kernel density of the
  drift-corrected dead-reckoned viewpoints, three-move look-ahead, a pull toward unvisited
  seen-free ground; :class:`lfmdr_gym.exploration.spread.SpreadPolicy`).
- ``"even"``: plans of three moves that keep the coverage of the room even (the room placed
  from the walls the ring sees, which also correct the dead reckoning; the moves simulated
  among cylinders fitted to every ring hit so far; :class:`lfmdr_gym.exploration.even.EvenPolicy`);
  the fastest mapper of these.
"""
