"""Recording: drive an env with a policy and stack what it senses into a :class:`History`.

:func:`collect` runs one episode of one env; :func:`collect_vector` runs episodes in every
sub-env of a Gymnasium vector env and copes with each autoreset mode. Both record, per move,
the mapping sensor's reading, the robot's true pose (for scoring only) and whether the move was
blocked; the reset observation is not a move and is never recorded. An env with imperfect
sensing (:mod:`lfmdr_gym.sim.sensing_limits`) also reports which objects it measured
(``"observed"``): that becomes the history's mask, True on every column of a measured object's step.
"""

from __future__ import annotations

import json
from collections.abc import Iterator
from contextlib import contextmanager
from typing import Any

import numpy as np

from lfmdr_gym.checks import check_int
from lfmdr_gym.exploration.contract import PredictPolicy, as_policy
from lfmdr_gym.histories.compact import COMPACT_ABOVE_BYTES, CompactSteps
from lfmdr_gym.histories.history import History, step_columns
from mappers.core.sensors import FUSED_SENSORS, SENSORS

__all__ = ["collect", "collect_vector"]


def _sensor_keys(observation: Any) -> tuple[str, tuple[str, ...]]:
    """The history's sensor name and the observation entries that hold it: one of
    "visibility", "bearing" or "range", or a fused set of them (:data:`FUSED_SENSORS`) whose
    entries are all recorded."""
    if not isinstance(observation, dict):
        raise ValueError(
            f"the env must return a dict observation holding one of {sorted(SENSORS)}, "
            f"got {type(observation).__name__} (a flattening wrapper cannot be recorded)"
        )
    keys = tuple(k for k in SENSORS if k in observation)
    if len(keys) == 1:
        return keys[0], keys
    named = {v: k for k, v in FUSED_SENSORS.items()}
    if frozenset(keys) not in named:
        raise ValueError(
            f"the observation must hold one sensor entry of {sorted(SENSORS)} or the entries of "
            f"a fused set {dict((k, sorted(v)) for k, v in FUSED_SENSORS.items())}, got keys "
            f"{sorted(observation)}"
        )
    return named[frozenset(keys)], keys


def _json_safe(mapping: dict[str, Any] | None) -> dict[str, Any]:
    """The entries of ``mapping`` that survive a JSON round trip (env kwargs for ``meta``)."""
    out: dict[str, Any] = {}
    for key, value in (mapping or {}).items():
        try:
            json.dumps(value)
        except (TypeError, ValueError):
            continue
        out[str(key)] = value
    return out


def _policy_seed(seed: int | None) -> int | None:
    """A seed for the policy's generator derived from the episode seed (never the same stream)."""
    if seed is None:
        return None
    return int(np.random.SeedSequence([int(seed), 0x706F6C]).generate_state(1)[0])


def _reset_policy(policy: Any, seed: int | None) -> None:
    reset = getattr(policy, "reset", None)
    if callable(reset):
        reset(seed=_policy_seed(seed))


def _policy_name(policy: Any) -> str:
    """How ``meta`` names the policy: its repr if its class defines one, else its name."""
    if type(policy).__repr__ is not object.__repr__ and not hasattr(policy, "__name__"):
        return repr(policy)
    return str(getattr(policy, "__name__", type(policy).__name__))


def _check_seed(seed: int | None) -> int | None:
    if seed is None:
        return None
    if isinstance(seed, bool) or not isinstance(seed, int | np.integer) or seed < 0:
        raise ValueError(f"seed must be a non-negative integer or None, got {seed!r}")
    return int(seed)


def _steps_to_matrix(buffer: np.ndarray, sensor: str, dimension: int = 2) -> np.ndarray:
    """(N, M, *c) per-step observations -> the (M, N * c) History matrix, c interleaved per step
    (c: :func:`~lfmdr_gym.histories.history.step_columns` of the sensor in ``dimension``-D)."""
    n, m = buffer.shape[:2]
    per_step = int(np.prod(buffer.shape[2:], dtype=int))
    columns = step_columns(sensor, dimension)
    if per_step != columns:
        raise ValueError(
            f"a {sensor!r} observation in {dimension}-D must give {columns} value(s) per object, "
            f"got shape {buffer.shape[1:]}"
        )
    return np.moveaxis(buffer, 0, 1).reshape(m, n * per_step).astype(np.float64)


def _steps_to_mask(observed: np.ndarray, sensor: str, dimension: int = 2) -> np.ndarray:
    """(N, M) per-step ``observed`` flags -> the (M, N * c) History mask: a step's flag covers
    each of its c columns (bearing: cos and sin; in 3-D the ray's x, y, z)."""
    c = step_columns(sensor, dimension)
    return np.repeat(observed.T.astype(bool), c, axis=1)


def _truth(info: dict[str, Any], index: int | None = None) -> dict[str, np.ndarray]:
    """Object positions and anchors from an env's info (row ``index`` of a vector env's info)."""
    out = {}
    for key in ("object_positions", "anchor_ids", "anchor_positions"):
        if key not in info:
            raise ValueError(f"the env's info lacks {key!r}; collect needs it to score the map")
        value = np.asarray(info[key])
        out[key] = np.array(value if index is None else value[index])
    return out


def _shaped_actions(action: Any, space: Any, batch: int | None) -> np.ndarray:
    """The policy's action(s) in the shape of the action space (with a leading sub-env axis of
    ``batch`` for a vector env); a mere reshape is allowed, anything else is a ValueError."""
    shape = tuple(space.shape or ()) if batch is None else (batch, *tuple(space.shape or ()))
    out = np.asarray(action, dtype=space.dtype)
    if out.shape == shape:
        return out
    if out.size == int(np.prod(shape, dtype=int)):
        return out.reshape(shape)
    if batch is None:
        raise ValueError(f"the policy returned an action of shape {out.shape}; the env's action "
                         f"space has shape {shape}")
    raise ValueError(
        f"the policy returned actions of shape {out.shape} for {batch} sub-environments; a policy "
        f"used with a vector env must answer a batched observation with shape {shape}"
    )


class _Episode:
    """What one episode's moves leave behind, move by move: each sensor's reading (one for a
    single sensor, several for a fused set: ``samples`` keyed by sensor), the env's "observed"
    flags (shared by the sensors of a set), the poses and blocked moves."""

    def __init__(self, n_steps: int, samples: dict[str, np.ndarray], truth: dict[str, np.ndarray],
                 masked: bool = False, compact: bool = False) -> None:
        self.n_steps = n_steps
        self.values: dict[str, Any] = {
            key: (CompactSteps(n_steps, sample, key, masked) if compact
                  else np.empty((n_steps, *sample.shape), dtype=sample.dtype))
            for key, sample in samples.items()}
        m = next(iter(samples.values())).shape[0]
        # the env's "observed" flags (imperfect sensing), one row per move; None without them
        # (a masked compact recording keeps them in each sensor's CompactSteps, sparsely)
        self.compact = bool(compact)
        self.observed = np.empty((n_steps, m), dtype=bool) if masked and not compact else None
        self.poses = np.empty((n_steps, 3), dtype=np.float64)
        self.truth = truth
        self.count = 0
        self.blocked = 0

    @property
    def full(self) -> bool:
        return self.count >= self.n_steps

    def record(self, values: dict[str, Any], pose: Any, blocked: Any, observed: Any = None) -> None:
        """Store one move (moves past ``n_steps`` are not recorded)."""
        if self.full:
            return
        for key, buffer in self.values.items():
            if self.compact and buffer.masked:
                buffer.record(values[key], observed)
            else:
                buffer[self.count] = values[key]
        if self.observed is not None:
            self.observed[self.count] = observed
        self.poses[self.count] = pose
        self.blocked += bool(blocked)
        self.count += 1

    def history(self, sensor: str, meta: dict[str, Any]) -> History:
        matrices, masks = {}, {}
        dimension = np.shape(self.truth["object_positions"])[1]  # 2, or 3 for a 3-D world
        for key, values in self.values.items():
            if self.compact:
                matrices[key] = values.matrix(key)
                masks[key] = values.mask() if values.masked else None
            else:
                matrices[key] = _steps_to_matrix(values, key, dimension)
                masks[key] = (None if self.observed is None
                              else _steps_to_mask(self.observed, key, dimension))
        single = len(matrices) == 1
        masked = any(m is not None for m in masks.values())
        return History(sensor=sensor, matrix=matrices[sensor] if single else matrices,
                       mask=(masks[sensor] if single else masks if masked else None),
                       robot_poses=self.poses, meta={**meta, "blocked_moves": int(self.blocked)},
                       **self.truth)


@contextmanager
def _env_from(env: Any, make_kwargs: dict[str, Any] | None) -> Iterator[Any]:
    """The env itself, or (for an env id) one made with ``make_kwargs`` and closed afterwards."""
    if not isinstance(env, str):
        if make_kwargs:
            raise ValueError("make_kwargs is only used when env is an env id string")
        yield env
        return
    import gymnasium as gym

    # The LFMDR ids are registered: importing this module ran lfmdr_gym/__init__.py first.
    made = gym.make(env, **(make_kwargs or {}))
    try:
        yield made
    finally:
        made.close()


def _meta(spec: Any, policy: Any, seed: int | None, n_steps: int, sensor: str) -> dict[str, Any]:
    return {
        "env_id": getattr(spec, "id", None),
        "env_kwargs": _json_safe(getattr(spec, "kwargs", None)),
        "seed": seed,
        "policy": _policy_name(policy),
        "policy_seed": _policy_seed(seed),
        "n_steps": n_steps,
        "sensor": sensor,
    }


def collect(
    env: Any,
    policy: Any,
    n_steps: int,
    seed: int | None = None,
    *,
    make_kwargs: dict[str, Any] | None = None,
    compact: bool | None = None,
) -> History:
    """Run one episode of ``n_steps`` moves and return what the robot sensed as a :class:`History`.

    ``env`` is a Gymnasium env with a dict observation (one sensor entry, or the entries of a
    fused set such as ``"range"`` and ``"bearing"``, which give a fused History, plus, for
    :class:`~lfmdr_gym.RandomWalkPolicy`, ``"proximity"``) and the ground truth in
    ``info``, or an env id (made with ``make_kwargs`` and closed afterwards). ``policy`` is anything
    :func:`~lfmdr_gym.exploration.contract.as_policy` accepts; its ``reset(seed=...)`` is called
    with a seed derived from ``seed``, so one seed fixes layout, start pose and walk. The
    observation after each move is column (or column pair) t of the matrix; the reset observation is
    not a move and is not recorded. Raises ValueError if the episode ends before ``n_steps`` moves.

    ``compact``: record the history in compact form (visibility and range sparse, bearing
    float32, a masked history's matrix and mask both sparse; see
    :mod:`lfmdr_gym.histories.compact`); None (default) does so only when the float64 matrix would
    exceed :data:`~lfmdr_gym.histories.compact.COMPACT_ABOVE_BYTES`, so small histories are as
    before.
    """
    n_steps = check_int("n_steps", n_steps, low=1)
    seed = _check_seed(seed)
    pol = as_policy(policy)
    with _env_from(env, make_kwargs) as env:
        spec = getattr(env, "spec", None)
        _check_limit(n_steps, getattr(spec, "max_episode_steps", None), "the env's")
        obs, info = env.reset(seed=seed)
        sensor, keys = _sensor_keys(obs)
        _reset_policy(pol, seed)
        samples = {k: np.asarray(obs[k]) for k in keys}
        if compact is None:
            compact = 8 * n_steps * sum(v.size for v in samples.values()) > COMPACT_ABOVE_BYTES
        elif not isinstance(compact, bool | np.bool_):
            raise ValueError(f"compact must be True, False or None, got {compact!r}")
        episode = _Episode(n_steps, samples, _truth(info), "observed" in obs, bool(compact))
        space = env.action_space  # (read once: through each wrapper, it is a chain of lookups)
        for t in range(n_steps):
            action = _shaped_actions(pol(obs), space, None)
            obs, _, terminated, truncated, info = env.step(action)
            episode.record(obs, info["robot_pose"], info.get("blocked", False),
                           obs.get("observed"))
            if (terminated or truncated) and t < n_steps - 1:
                raise ValueError(
                    f"the episode ended after {t + 1} of n_steps={n_steps} moves "
                    f"({'terminated' if terminated else 'truncated'}); n_steps must not exceed "
                    "the env's max_episode_steps"
                )
        return episode.history(sensor, _meta(spec, pol, seed, n_steps, sensor))


def _check_limit(n_steps: int, limit: int | None, whose: str) -> None:
    if limit is not None and n_steps > limit:
        raise ValueError(
            f"n_steps={n_steps} exceeds {whose} max_episode_steps={limit}: the episode would be "
            "truncated first; make the env with a larger max_episode_steps"
        )


class _VectorRecorder:
    """Episodes of every sub-env of a vector env, filled as the sub-envs step and reset."""

    def __init__(self, n_steps: int, n_episodes: int, samples: dict[str, np.ndarray], info: dict,
                 masked: bool) -> None:
        self.n_steps, self.n_episodes = n_steps, n_episodes
        self.batch = len(next(iter(samples.values())))
        self.masked = masked  # the sub-envs report "observed" (imperfect sensing)
        # the shape and dtype of one sub-env's readings
        self.sample = {k: np.empty_like(v[0]) for k, v in samples.items()}
        self.episodes = [[_Episode(n_steps, {k: v[i] for k, v in samples.items()}, _truth(info, i),
                                   masked)]
                         for i in range(self.batch)]
        self.starts = np.ones(self.batch, dtype=bool)  # episode_start flags for SB3-style policies

    def record(self, rows: Any, values: dict[str, np.ndarray], step_info: dict[str, Any],
               observed: np.ndarray | None = None) -> None:
        blocked = step_info.get("blocked")
        for i in rows:
            if len(self.episodes[i]) <= self.n_episodes:
                self.episodes[i][-1].record({k: v[i] for k, v in values.items()},
                                            step_info["robot_pose"][i],
                                            False if blocked is None else blocked[i],
                                            None if observed is None else observed[i])

    def new_episode(self, rows: Any, reset_info: dict[str, Any]) -> None:
        for i in rows:
            done = len(self.episodes[i])
            if done <= self.n_episodes and not self.episodes[i][-1].full:
                raise ValueError(
                    f"sub-env {i}'s episode {done - 1} ended after {self.episodes[i][-1].count} "
                    f"of n_steps={self.n_steps} moves; n_steps must not exceed max_episode_steps"
                )
            self.starts[i] = True
            # past the last wanted episode, an empty placeholder marks the sub-env as finished
            self.episodes[i].append(_Episode(self.n_steps, self.sample, _truth(reset_info, i),
                                             self.masked)
                                    if done < self.n_episodes else _Episode(0, self.sample, {}))

    def finished(self) -> bool:
        return all(len(eps) > self.n_episodes
                   or (len(eps) == self.n_episodes and eps[-1].full) for eps in self.episodes)


def _vector_step(envs: Any, mode: Any, action: np.ndarray, keys: tuple[str, ...],
                 rec: _VectorRecorder, pending: np.ndarray) -> tuple[Any, np.ndarray]:
    """One step of every sub-env, recorded as the autoreset mode requires; returns the new
    observation and the NEXT_STEP rows whose next step is a reset."""
    from gymnasium.vector import AutoresetMode

    obs, _, terminated, truncated, info = envs.step(action)
    done = np.asarray(terminated) | np.asarray(truncated)
    seen = np.asarray(obs["observed"]) if rec.masked else None
    if mode == AutoresetMode.NEXT_STEP:  # the step after an end only resets: not a move
        rec.record(np.flatnonzero(~pending), {k: np.asarray(obs[k]) for k in keys}, info, seen)
        rec.new_episode(np.flatnonzero(pending), info)
        return obs, done & ~pending
    if mode == AutoresetMode.SAME_STEP:  # the move's own observation is in final_obs
        values = {k: np.asarray(obs[k]).copy() for k in keys}
        seen = None if seen is None else seen.copy()
        step_info = {k: np.array(v, copy=True) for k, v in info.items()
                     if k in ("robot_pose", "blocked")}
        ended = np.flatnonzero(done)
        for i in ended:
            for k in keys:
                values[k][i] = info["final_obs"][i][k]
            if seen is not None:
                seen[i] = info["final_obs"][i]["observed"]
            for key in step_info:
                step_info[key][i] = info["final_info"][key][i]
        rec.record(range(rec.batch), values, step_info, seen)
        rec.new_episode(ended, info)
        return obs, pending
    # DISABLED: we reset ourselves
    rec.record(range(rec.batch), {k: np.asarray(obs[k]) for k in keys}, info, seen)
    if done.any():
        obs, reset_info = envs.reset(options={"reset_mask": done})
        rec.new_episode(np.flatnonzero(done), reset_info)
    return obs, pending


def collect_vector(
    envs: Any,
    policy: Any,
    n_steps: int,
    seed: int | None = None,
    *,
    n_episodes: int = 1,
) -> list[History]:
    """Record ``n_episodes`` episodes of ``n_steps`` moves in every sub-env of a vector env.

    ``envs`` is a ``gymnasium.vector.VectorEnv`` (e.g. ``gymnasium.make_vec(id, num_envs=4)``),
    reset with ``seed`` (sub-env i gets ``seed + i``; later episodes continue each sub-env's
    random stream, as its autoreset does). ``policy`` must accept batched observations (leading
    sub-env axis) and return one action per sub-env. Returns the histories sub-env by sub-env:
    index ``i * n_episodes + e`` is episode e of sub-env i.

    Autoreset is handled for every mode: with NEXT_STEP (Gymnasium's default) the step after an
    episode ends only resets that sub-env, so it is not recorded as a move; with SAME_STEP the
    move's observation is taken from ``info["final_obs"]``; with DISABLED the collector resets
    the finished sub-envs itself. Moves past ``n_steps`` in an episode are run but not recorded
    (make the env with ``max_episode_steps=n_steps`` when collecting several episodes). An
    episode that ends before ``n_steps`` moves raises ValueError.
    """
    from gymnasium.vector import AutoresetMode


    n_steps = check_int("n_steps", n_steps, low=1)
    seed = _check_seed(seed)
    n_episodes = check_int("n_episodes", n_episodes, low=1)
    if not hasattr(envs, "num_envs") or not hasattr(envs, "single_action_space"):
        raise ValueError(f"envs must be a gymnasium VectorEnv, got {type(envs).__name__}")
    pol = as_policy(policy)
    mode = AutoresetMode(envs.metadata.get("autoreset_mode", AutoresetMode.NEXT_STEP))
    spec = getattr(envs, "spec", None)
    # make_vec keeps the registered limit in spec.max_episode_steps and an override in its kwargs
    _check_limit(n_steps, (getattr(spec, "kwargs", None) or {}).get(
        "max_episode_steps", getattr(spec, "max_episode_steps", None)), "the sub-envs'")
    obs, info = envs.reset(seed=seed)
    sensor, keys = _sensor_keys(obs)
    _reset_policy(pol, seed)
    rec = _VectorRecorder(n_steps, n_episodes, {k: np.asarray(obs[k]) for k in keys}, info,
                          "observed" in obs)
    pending = np.zeros(rec.batch, dtype=bool)  # NEXT_STEP: this sub-env's next step is a reset
    while not rec.finished():
        starts, rec.starts = rec.starts, np.zeros(rec.batch, dtype=bool)
        action = pol(obs, episode_start=starts) if isinstance(pol, PredictPolicy) else pol(obs)
        obs, pending = _vector_step(envs, mode, _shaped_actions(action, envs.single_action_space,
                                                                rec.batch), keys, rec, pending)
    meta = {**_meta(spec, pol, seed, n_steps, sensor), "num_envs": rec.batch,
            "autoreset_mode": mode.value}
    histories = []
    for i, episodes in enumerate(rec.episodes):
        for e, episode in enumerate(episodes[:n_episodes]):
            first = {} if seed is None else {"first_episode_seed": seed + i}
            seed_i = (seed + i) if (seed is not None and e == 0) else None
            histories.append(episode.history(sensor, {**meta, "seed": seed_i, "sub_env": i,
                                                      "episode": e, **first}))
    return histories
