"""Episodes: the random walks the experiments map, collected reproducibly from seeds.

A protocol episode is a layout (drawn from one seed) walked from a start pose (drawn from
another), so the five poses of a layout share its objects and anchors (paper §4.1). One episode
of any env can also be collected on its own (``lfmdr collect``, ``lfmdr run``).
"""

from __future__ import annotations

import os
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from lfmdr_gym.checks import check_int
from lfmdr_gym.experiments.store import ensure_writable_dir
from lfmdr_gym.histories.history import History

__all__ = ["Episode", "collect_episode", "collect_history", "derived_seed", "describe_history"]


def derived_seed(*parts: int) -> int:
    """A 31-bit seed derived from integers; independent streams for layouts and poses."""
    return int(np.random.SeedSequence([int(p) for p in parts]).generate_state(1)[0] & 0x7FFFFFFF)


@dataclass(frozen=True)
class Episode:
    """One protocol run: a layout (fixed by ``layout_seed``) and a start pose (by ``pose_seed``)."""

    env_id: str
    layout: int
    pose: int
    layout_seed: int
    pose_seed: int
    steps: int
    env_kwargs: tuple[tuple[str, Any], ...] = ()  # env keywords, e.g. (("fov_deg", 90),)

    @property
    def name(self) -> str:
        return f"L{self.layout}_P{self.pose}"


def make_env(env_id: str, steps: int, env_kwargs: Mapping[str, Any] | None = None) -> Any:
    """``gym.make(env_id)`` with an episode limit of ``steps`` and the given env keywords.

    An id Gymnasium does not know is a ValueError naming the registered LFMDR ids (any other
    registered Gymnasium id is made as it is)."""
    import gymnasium as gym

    import lfmdr_gym  # noqa: F401 - registers the env ids

    if env_id not in gym.registry:
        raise ValueError(f"unknown env id {env_id!r}; the registered LFMDR env ids are "
                         f"{list(lfmdr_gym.ENV_IDS)} and (3-D) {list(lfmdr_gym.ENV_IDS_3D)}")
    return gym.make(env_id, max_episode_steps=max(int(steps), 1), **dict(env_kwargs or {}))


def _fixed_layout(env: Any, layout: Mapping[str, np.ndarray]) -> Any:
    """``env`` wrapped so that every reset passes the same layout in ``options``."""
    import gymnasium as gym

    class FixedLayout(gym.Wrapper):
        def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
            return self.env.reset(seed=seed, options={**layout, **(options or {})})

    return FixedLayout(env)


def collect_episode(episode: Episode) -> History:
    """Collect one protocol episode with the random-walk agent.

    The layout comes from ``layout_seed`` (a reset with that seed draws it), the start pose and the
    agent's random stream from ``pose_seed``; the layout is held fixed through reset options, so
    the five poses of a layout share its objects and anchors.
    """
    from lfmdr_gym.exploration.random_walk import RandomWalkPolicy
    from lfmdr_gym.histories.recording import collect

    env = make_env(episode.env_id, episode.steps, dict(episode.env_kwargs))
    try:
        _, info = env.reset(seed=episode.layout_seed)
        layout = {
            "object_positions": np.array(info["object_positions"], dtype=np.float64),
            "anchor_ids": np.array(info["anchor_ids"], dtype=np.int64),
        }
        fixed = _fixed_layout(env, layout)
        policy = RandomWalkPolicy.for_env(env, seed=episode.pose_seed)
        history = collect(fixed, policy, episode.steps, seed=episode.pose_seed)
    finally:
        env.close()
    return history.replace(meta={
        **history.meta, "env_id": episode.env_id, "layout": episode.layout, "pose": episode.pose,
        "layout_seed": episode.layout_seed, "pose_seed": episode.pose_seed,
    })


def collect_history(
    env_id: str, steps: int, seed: int | None = 0, out: str | os.PathLike | None = None,
    env_kwargs: Mapping[str, Any] | None = None,
    policy: str = "random-walk",
) -> History:
    """One episode of ``env_id`` (layout and pose from ``seed``; ``env_kwargs``: env keywords
    such as ``{"fov_deg": 90}``, checked for the LFMDR ids) driven by the exploration policy
    named ``policy`` (:data:`lfmdr_gym.POLICIES`), saved to ``out``."""
    from lfmdr_gym import ENV_IDS
    from lfmdr_gym.experiments.env_settings import check_env_kwargs

    if env_kwargs and env_id in ENV_IDS:
        env_kwargs, _ = check_env_kwargs(ENV_IDS[env_id], env_kwargs)
    from lfmdr_gym.exploration import POLICIES
    from lfmdr_gym.histories.recording import collect

    if policy not in POLICIES:
        raise ValueError(f"unknown policy {policy!r}; choose from {list(POLICIES)}")

    check_int("steps", steps, low=1)
    if out is not None:
        out = Path(out)
        if out.suffix != ".npz":
            raise ValueError(f"the history file must end in .npz, got {out.name!r}")
        ensure_writable_dir(out.parent)
    env = make_env(env_id, steps, env_kwargs)
    try:
        agent = POLICIES[policy](env, seed=seed)
        history = collect(env, agent, int(steps), seed=seed)
    finally:
        env.close()
    history = history.replace(meta={**history.meta, "env_id": env_id, "seed": seed})
    if out is not None:
        history.save(out)
    return history


def describe_history(history: History) -> str:
    """A few lines summarising a history: size, sensor, how much each object was sensed."""
    lines = [repr(history)]
    if history.sensor == "visibility":
        seen = history.matrix.sum(axis=1)
        lines.append(
            f"sightings per object: min {int(seen.min())}, median {float(np.median(seen)):g}, "
            f"max {int(seen.max())}; never seen: {int((seen == 0).sum())} objects; "
            f"visible per step: {history.matrix.sum(axis=0).mean():.2f} objects on average"
        )
    if history.fused and history.mask is not None:
        lines.append("observed entries: " + ", ".join(
            f"{name} {100 * (1.0 if m is None else m.mean()):.1f} %"
            for name, m in history.mask.items()))
    elif history.mask is not None:
        lines.append(f"observed entries: {100 * history.mask.mean():.1f} %")
    if history.robot_poses is not None and history.n_steps > 1:
        moves = np.linalg.norm(np.diff(history.robot_poses[:, :2], axis=0), axis=1)
        blocked = history.meta.get("blocked_moves")
        lines.append(f"robot path: {moves.sum():.1f} m over {history.n_steps} steps "
                     f"(mean move {moves.mean():.3f} m"
                     + (f"; {blocked} moves blocked by an obstacle)" if blocked is not None else ")"))
    meta = {k: v for k, v in history.meta.items() if k in ("env_id", "seed", "layout", "pose")}
    if meta:
        lines.append("from " + ", ".join(f"{k}={v}" for k, v in meta.items()))
    return "\n".join(lines)
