"""The reinforcement-learned exploration policy, run in numpy from a small shipped weights file.

``examples/train_rl_policy.py`` trains a Stable-Baselines3 PPO agent on
:class:`~lfmdr_gym.wrappers.MappingRewardWrapper` and exports its actor (an MLP with tanh
hidden layers) with :func:`export_sb3`. :class:`MLPExplorationPolicy` reads that file and
computes the deterministic action with numpy alone (``tanh(W h + b)`` per hidden layer, a linear
output clipped to [-1, 1], as SB3's ``predict(..., deterministic=True)`` does for a Gaussian
policy on a Box(-1, 1) action space), so the registered ``"rl"`` policy needs neither torch
nor SB3. Its features and the shield come from the same
:class:`~lfmdr_gym.exploration.agent_view.AgentView` as in training.

File format (``.npz``, loaded with ``allow_pickle=False``): ``weight_0``, ``bias_0``, ... per
layer (weights as (out, in), as torch stores them) and ``config``, a JSON string with the
:class:`~lfmdr_gym.exploration.agent_view.ViewConfig` the agent was trained with and ``format`` = 1.
"""

from __future__ import annotations

import json
import os
from collections.abc import Mapping
from importlib import resources
from pathlib import Path
from typing import Any

import numpy as np

from lfmdr_gym.exploration.agent_view import AgentView, ViewConfig
from lfmdr_gym.exploration.random_walk import RandomWalkPolicy

__all__ = ["DEFAULT_MODEL", "MLPExplorationPolicy", "export_sb3", "load_mlp"]

FORMAT = 1
DEFAULT_MODEL = "rl_policy.npz"
"""The shipped model, in the package folder ``lfmdr_gym/models``."""

# The geometry that must match between the env and the trained model (the visit grid's cell
# and extent and the feature options come from the model file: part of what the agent learned).
STUCK_STEPS = 8
"""Observations in contact in a row after which :class:`MLPExplorationPolicy` lets the random
walk choose the turn instead of the network: the largest of 3, 5 and 8 that freed every one of
40 layouts per sensor (seeds 0-39, 500 steps; without it 3 bearing layouts and 1 visibility
layout had 260-453 of the 500 moves blocked, with it at most 68)."""

_MATCHED = ("n_rays", "proximity_range", "max_turn", "step_length", "robot_radius",
            "object_radius")


def _model_path(model: str | os.PathLike | None) -> Path:
    if model is None:
        return Path(str(resources.files("lfmdr_gym") / "models" / DEFAULT_MODEL))
    return Path(model)


def load_mlp(model: str | os.PathLike | None = None) -> tuple[list[tuple[np.ndarray, np.ndarray]], dict]:
    """The layers ``[(W, b), ...]`` and the config dict of a model file (the shipped one by default)."""
    path = _model_path(model)
    if not path.is_file():
        raise FileNotFoundError(f"no RL policy model at {path}; train one with "
                                "examples/train_rl_policy.py")
    with np.load(path, allow_pickle=False) as data:
        try:
            config = json.loads(str(data["config"]))
        except KeyError as exc:
            raise ValueError(f"{path} is not an RL policy model: it has no 'config' entry") from exc
        if config.get("format") != FORMAT:
            raise ValueError(f"{path}: unknown model format {config.get('format')!r} "
                             f"(this version reads {FORMAT})")
        layers = []
        while f"weight_{len(layers)}" in data:
            k = len(layers)
            layers.append((data[f"weight_{k}"].astype(np.float64), data[f"bias_{k}"].astype(np.float64)))
    if not layers:
        raise ValueError(f"{path} holds no layers (weight_0, bias_0, ...)")
    n_in = layers[0][0].shape[1]
    for k, (w, b) in enumerate(layers):
        if w.ndim != 2 or b.shape != (w.shape[0],) or w.shape[1] != n_in:
            raise ValueError(f"{path}: layer {k} has weight {w.shape} and bias {b.shape}, which "
                             f"do not chain from an input of {n_in}")
        n_in = w.shape[0]
    if n_in != 1:
        raise ValueError(f"{path}: the last layer gives {n_in} outputs, the action needs 1")
    return layers, config


def mlp_forward(layers: list[tuple[np.ndarray, np.ndarray]], x: np.ndarray) -> np.ndarray:
    """The deterministic action for features ``x`` (n,) or (B, n): tanh hidden layers, a linear
    output clipped to [-1, 1]."""
    h = np.asarray(x, dtype=np.float64)
    for w, b in layers[:-1]:
        h = np.tanh(h @ w.T + b)
    w, b = layers[-1]
    return np.clip(h @ w.T + b, -1.0, 1.0)


def export_sb3(model: Any, path: str | os.PathLike, config: ViewConfig) -> Path:
    """Write a trained SB3 PPO/A2C ``MlpPolicy`` actor (tanh activations) to ``path`` (atomic).

    Reads ``model.policy.mlp_extractor.policy_net`` (Linear/Tanh pairs) and
    ``model.policy.action_net``; refuses other architectures with a ValueError naming the part.
    """
    from lfmdr_gym.atomic import atomic_write

    policy = model.policy
    linears = []
    for module in policy.mlp_extractor.policy_net:
        kind = type(module).__name__
        if kind == "Linear":
            linears.append(module)
        elif kind != "Tanh":
            raise ValueError(f"the policy network has a {kind} layer; only Linear and Tanh "
                             "(SB3's MlpPolicy with activation_fn=nn.Tanh) are exported")
    linears.append(policy.action_net)
    arrays = {}
    for k, lin in enumerate(linears):
        arrays[f"weight_{k}"] = lin.weight.detach().cpu().numpy().astype(np.float32)
        arrays[f"bias_{k}"] = lin.bias.detach().cpu().numpy().astype(np.float32)
    meta = {"format": FORMAT, **config.as_dict()}
    arrays["config"] = np.array(json.dumps(meta))
    path = Path(path)
    with atomic_write(path, "wb") as fh:
        np.savez_compressed(fh, **arrays)
    return path


class MLPExplorationPolicy:
    """An exploration policy from a trained MLP (module docstring); one observation at a time.

    Args:
        config: the env's geometry (:meth:`ViewConfig.for_env`); must match the model's.
        model: path of a model file; None for the shipped one.
        seed: accepted for the registry's interface; the policy is deterministic.

    Sees observations only: its state is the :class:`~lfmdr_gym.exploration.agent_view.AgentView`
    memory of this episode and the turn it made last; :meth:`reset` forgets both.
    """

    def __init__(self, config: ViewConfig, model: str | os.PathLike | None = None, *,
                 seed: int | None = None) -> None:
        self.layers, meta = load_mlp(model)
        self.model = str(_model_path(model))
        trained = {k: meta[k] for k in _MATCHED if k in meta}
        for key, value in trained.items():
            if not np.isclose(float(getattr(config, key)), float(value)):
                raise ValueError(f"the model was trained with {key}={value}, the env has "
                                 f"{key}={getattr(config, key)}; train a model for this env")
        learned = {k: meta[k] for k in ("cell", "extent", "correct_drift", "presence") if k in meta}
        config = ViewConfig(**{**config.as_dict(), **learned})
        if self.layers[0][0].shape[1] != config.n_features:
            raise ValueError(f"the model takes {self.layers[0][0].shape[1]} features, the view "
                             f"gives {config.n_features}")
        self.view = AgentView(config)
        self.seed = seed
        self._turn: float | None = None
        self._contacts = 0
        # the random walk that takes over while the robot is stuck (reseeded every episode)
        self._escape = RandomWalkPolicy(config.max_turn, config.step_length, config.robot_radius,
                                        obstacle_radius=config.object_radius, seed=0)

    @classmethod
    def for_env(cls, env: Any, model: str | os.PathLike | None = None,
                **kwargs: Any) -> MLPExplorationPolicy:
        """The policy for ``env``'s geometry and spaces (the shipped model by default)."""
        return cls(ViewConfig.for_env(env), model, **kwargs)

    def reset(self, seed: int | None = None) -> None:
        """Start an episode: the next observation is the first."""
        self._turn = None
        self._contacts = 0
        self._escape.reset(0 if seed is None else seed)
        if seed is not None:
            self.seed = seed

    def __call__(self, observation: Mapping[str, Any]) -> np.ndarray:
        """The heading change for one observation, shape (1,)."""
        if self._turn is None:
            features = self.view.reset(observation)
            self._contacts = 0
        else:
            features, _ = self.view.step(self._turn, observation)
        # A deterministic policy pressed against an obstacle repeats the move the physics stops
        # (measured: on 3 of 40 bearing layouts most of 500 moves were blocked); after
        # STUCK_STEPS observations in contact in a row the random walk chooses the turn (its
        # random draws find the way out of a pocket that fixed turns keep missing).
        self._contacts = self._contacts + 1 if self.view.in_contact else 0
        if self._contacts >= STUCK_STEPS:
            self._turn = float(np.float32(self._escape(observation)[0]))
        else:
            self._turn = self.view.turn_for(mlp_forward(self.layers, features))
        return np.array([self._turn], np.float32)

    def __repr__(self) -> str:
        return f"MLPExplorationPolicy(model={self.model!r})"
