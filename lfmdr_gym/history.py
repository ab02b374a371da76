"""Observation histories: the per-object matrix a mapper takes, plus the ground truth that scores it.

A :class:`History` is what one episode (or one logged run) leaves behind. Its ``matrix`` has one
row per object and, per step, ``columns_per_step`` columns: 1 for visibility (0/1) and range,
2 for bearing (cos, sin). Columns are in step order, so the first ``n`` steps of a history are
its first ``n * columns_per_step`` columns (:meth:`History.head`).

Ground truth (object positions, robot poses) travels with the history for scoring only; a mapper
is given the matrix and the anchors, nothing else.
"""

from __future__ import annotations

import json
import os
import zipfile
import zlib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from lfmdr_gym.atomic import atomic_write

SENSORS: dict[str, int] = {"visibility": 1, "bearing": 2, "range": 1}
"""Sensor kinds and the number of matrix columns each step contributes."""

FORMAT = "lfmdr-history"
FORMAT_VERSION = 1


class HistoryFileError(ValueError):
    """A file that is not a readable lfmdr history (damaged, foreign, or of another version)."""


@dataclass(frozen=True, eq=False)
class History:
    """Per-object observation histories of one episode, with the ground truth to score a map.

    Attributes:
        sensor: ``"visibility"``, ``"bearing"`` or ``"range"``.
        matrix: (M, N * columns_per_step) float64, one row per object.
        object_positions: (M, 2) true object positions [m] (NaN where unknown).
        anchor_ids: (A,) indices of the anchor objects, A >= 3.
        anchor_positions: (A, 2) known positions of the anchors [m].
        robot_poses: (N, 3) true robot pose (x, y, heading) after each step, or None for
            logged data without it. Never given to a mapper.
        mask: None when every entry was observed, else a (M, N * columns_per_step) bool array,
            True where the entry was observed.
        meta: JSON-serialisable facts about where the history came from (env id, seed, ...).
    """

    sensor: str
    matrix: np.ndarray
    object_positions: np.ndarray
    anchor_ids: np.ndarray
    anchor_positions: np.ndarray
    robot_poses: np.ndarray | None = None
    mask: np.ndarray | None = None
    meta: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        if self.sensor not in SENSORS:
            raise ValueError(f"sensor must be one of {sorted(SENSORS)}, got {self.sensor!r}")
        matrix = np.asarray(self.matrix, dtype=np.float64)
        if matrix.ndim != 2:
            raise ValueError(f"matrix must be 2-D (objects x columns), got shape {matrix.shape}")
        m, d = matrix.shape
        if d % SENSORS[self.sensor]:
            raise ValueError(
                f"matrix has {d} columns, not a multiple of {SENSORS[self.sensor]} "
                f"(columns per step for {self.sensor!r})"
            )
        obj = np.asarray(self.object_positions, dtype=np.float64)
        if obj.shape != (m, 2):
            raise ValueError(f"object_positions must have shape ({m}, 2), got {obj.shape}")
        ids = np.asarray(self.anchor_ids)
        if ids.ndim != 1 or not np.issubdtype(ids.dtype, np.integer):
            raise ValueError(f"anchor_ids must be a 1-D integer array, got {ids.dtype} {ids.shape}")
        ids = ids.astype(np.int64)
        if ids.size and (ids.min() < 0 or ids.max() >= m):
            raise ValueError(f"anchor_ids must lie in [0, {m}), got {ids.tolist()}")
        apos = np.asarray(self.anchor_positions, dtype=np.float64)
        if apos.shape != (ids.size, 2):
            raise ValueError(f"anchor_positions must have shape ({ids.size}, 2), got {apos.shape}")
        poses = None
        if self.robot_poses is not None:
            poses = np.asarray(self.robot_poses, dtype=np.float64)
            if poses.ndim != 2 or poses.shape[1] != 3:
                raise ValueError(f"robot_poses must have shape (N, 3), got {poses.shape}")
            if poses.shape[0] != d // SENSORS[self.sensor]:
                raise ValueError(
                    f"robot_poses has {poses.shape[0]} rows for {d // SENSORS[self.sensor]} steps"
                )
        mask = None
        if self.mask is not None:
            mask = np.asarray(self.mask)
            if mask.dtype != np.bool_ or mask.shape != matrix.shape:
                raise ValueError(
                    f"mask must be a bool array of shape {matrix.shape}, got {mask.dtype} {mask.shape}"
                )
        object.__setattr__(self, "matrix", matrix)
        object.__setattr__(self, "object_positions", obj)
        object.__setattr__(self, "anchor_ids", ids)
        object.__setattr__(self, "anchor_positions", apos)
        object.__setattr__(self, "robot_poses", poses)
        object.__setattr__(self, "mask", mask)
        object.__setattr__(self, "meta", dict(self.meta))

    # ------------------------------------------------------------------ views
    @property
    def columns_per_step(self) -> int:
        return SENSORS[self.sensor]

    @property
    def n_objects(self) -> int:
        return self.matrix.shape[0]

    @property
    def n_steps(self) -> int:
        return self.matrix.shape[1] // self.columns_per_step

    def head(self, n_steps: int) -> History:
        """The history of the first ``n_steps`` steps (a checkpoint of the same episode)."""
        if not 0 < n_steps <= self.n_steps:
            raise ValueError(f"n_steps must be in [1, {self.n_steps}], got {n_steps}")
        cols = n_steps * self.columns_per_step
        return History(
            sensor=self.sensor,
            matrix=self.matrix[:, :cols],
            object_positions=self.object_positions,
            anchor_ids=self.anchor_ids,
            anchor_positions=self.anchor_positions,
            robot_poses=None if self.robot_poses is None else self.robot_poses[:n_steps],
            mask=None if self.mask is None else self.mask[:, :cols],
            meta=self.meta,
        )

    def __repr__(self) -> str:
        return (
            f"History(sensor={self.sensor!r}, objects={self.n_objects}, steps={self.n_steps}, "
            f"anchors={self.anchor_ids.tolist()}, masked={self.mask is not None})"
        )

    # ------------------------------------------------------------------ files
    def save(self, path: str | os.PathLike) -> Path:
        """Write the history to ``path`` (.npz) atomically: a reader never sees a half-written file."""
        path = Path(path)
        if path.suffix != ".npz":
            raise ValueError(f"history files end in .npz, got {path.name!r}")
        arrays: dict[str, np.ndarray] = {
            "format": np.array(FORMAT),
            "format_version": np.array(FORMAT_VERSION),
            "sensor": np.array(self.sensor),
            "matrix": self.matrix,
            "object_positions": self.object_positions,
            "anchor_ids": self.anchor_ids,
            "anchor_positions": self.anchor_positions,
            "meta": np.array(json.dumps(self.meta, sort_keys=True)),
        }
        if self.robot_poses is not None:
            arrays["robot_poses"] = self.robot_poses
        if self.mask is not None:
            arrays["mask"] = self.mask
        with atomic_write(path, "wb") as fh:
            np.savez_compressed(fh, **arrays)
        return path

    @classmethod
    def load(cls, path: str | os.PathLike) -> History:
        """Read a history written by :meth:`save`; anything else raises :class:`HistoryFileError`."""
        path = Path(path)
        if not path.is_file():
            raise FileNotFoundError(f"no history file at {path}")
        try:
            with np.load(path, allow_pickle=False) as data:
                files = set(data.files)
                if "format" not in files or str(data["format"]) != FORMAT:
                    raise HistoryFileError(f"{path} is not an lfmdr history file (no '{FORMAT}' tag)")
                version = int(data["format_version"])
                if version != FORMAT_VERSION:
                    raise HistoryFileError(
                        f"{path} has history format version {version}; this lfmdr reads {FORMAT_VERSION}"
                    )
                fields = {k: data[k] for k in files}
        except HistoryFileError:
            raise
        except (OSError, ValueError, EOFError, KeyError, zipfile.BadZipFile, zlib.error,
                NotImplementedError) as exc:  # zlib.error / NotImplementedError: damaged members
            raise HistoryFileError(f"{path} is damaged or not an .npz history: {exc}") from exc
        try:
            return cls(
                sensor=str(fields["sensor"]),
                matrix=fields["matrix"],
                object_positions=fields["object_positions"],
                anchor_ids=fields["anchor_ids"],
                anchor_positions=fields["anchor_positions"],
                robot_poses=fields.get("robot_poses"),
                mask=fields.get("mask"),
                meta=json.loads(str(fields["meta"])),
            )
        except KeyError as exc:
            raise HistoryFileError(f"{path} lacks the field {exc.args[0]!r}") from exc
        except ValueError as exc:
            raise HistoryFileError(f"{path} holds an inconsistent history: {exc}") from exc


# ---------------------------------------------------------------------- recording
# collect() / collect_vector(): drive an env with a policy and stack what it senses into a History.
# gymnasium is imported inside them so that History itself stays importable without it.

def _sensor_key(observation: Any) -> str:
    """The observation entry that holds the mapping sensor ("visibility", "bearing" or "range")."""
    if not isinstance(observation, dict):
        raise ValueError(
            f"the env must return a dict observation holding one of {sorted(SENSORS)}, "
            f"got {type(observation).__name__} (a flattening wrapper cannot be recorded)"
        )
    keys = [k for k in SENSORS if k in observation]
    if len(keys) != 1:
        raise ValueError(
            f"the observation must hold exactly one sensor entry of {sorted(SENSORS)}, "
            f"got keys {sorted(observation)}"
        )
    return keys[0]


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


def _check_n_steps(n_steps: int) -> int:
    if isinstance(n_steps, bool) or not isinstance(n_steps, int | np.integer) or n_steps < 1:
        raise ValueError(f"n_steps must be a positive integer, got {n_steps!r}")
    return int(n_steps)


def _steps_to_matrix(buffer: np.ndarray, sensor: str) -> np.ndarray:
    """(N, M, *c) per-step observations -> the (M, N * c) History matrix, c interleaved per step."""
    n, m = buffer.shape[:2]
    per_step = int(np.prod(buffer.shape[2:], dtype=int))
    if per_step != SENSORS[sensor]:
        raise ValueError(
            f"a {sensor!r} observation must give {SENSORS[sensor]} value(s) per object, "
            f"got shape {buffer.shape[1:]}"
        )
    return np.moveaxis(buffer, 0, 1).reshape(m, n * per_step).astype(np.float64)


def _truth(info: dict[str, Any], index: int | None = None) -> dict[str, np.ndarray]:
    """Object positions and anchors from an env's info (row ``index`` of a vector env's info)."""
    out = {}
    for key in ("object_positions", "anchor_ids", "anchor_positions"):
        if key not in info:
            raise ValueError(f"the env's info lacks {key!r}; collect needs it to score the map")
        value = np.asarray(info[key])
        out[key] = np.array(value if index is None else value[index])
    return out


def collect(
    env: Any,
    policy: Any,
    n_steps: int,
    seed: int | None = None,
    *,
    make_kwargs: dict[str, Any] | None = None,
) -> History:
    """Run one episode of ``n_steps`` moves and return what the robot sensed as a :class:`History`.

    ``env`` is a Gymnasium env with a dict observation (one sensor entry plus, for
    :class:`~lfmdr_gym.policies.RandomWalkPolicy`, ``"proximity"``) and the ground truth in
    ``info``, or an env id (made with ``make_kwargs`` and closed afterwards). ``policy`` is anything
    :func:`~lfmdr_gym.policies.as_policy` accepts; its ``reset(seed=...)`` is called with a seed
    derived from ``seed``, so one seed fixes layout, start pose and walk. The observation after
    each move is column (or column pair) t of the matrix; the reset observation is not a move and
    is not recorded. Raises ValueError if the episode ends before ``n_steps`` moves.
    """
    import gymnasium as gym

    from lfmdr_gym.policies import as_policy

    n_steps = _check_n_steps(n_steps)
    seed = _check_seed(seed)
    pol = as_policy(policy)
    owned = isinstance(env, str)
    if owned:
        import lfmdr_gym  # noqa: F401  (registers the LFMDR ids)

        env = gym.make(env, **(make_kwargs or {}))
    elif make_kwargs:
        raise ValueError("make_kwargs is only used when env is an env id string")
    try:
        spec = getattr(env, "spec", None)
        limit = getattr(spec, "max_episode_steps", None)
        if limit is not None and n_steps > limit:
            raise ValueError(
                f"n_steps={n_steps} exceeds the env's max_episode_steps={limit}: the episode "
                "would be truncated; make the env with a larger max_episode_steps"
            )
        space = env.action_space
        action_shape = tuple(space.shape or ())
        action_dtype = space.dtype

        obs, info = env.reset(seed=seed)
        sensor = _sensor_key(obs)
        truth = _truth(info)
        _reset_policy(pol, seed)
        first = np.asarray(obs[sensor])
        buffer = np.empty((n_steps, *first.shape), dtype=first.dtype)
        poses = np.empty((n_steps, 3), dtype=np.float64)
        blocked = 0
        for t in range(n_steps):
            action = np.asarray(pol(obs), dtype=action_dtype)
            if action.shape != action_shape:
                if action.size != int(np.prod(action_shape, dtype=int)):
                    raise ValueError(
                        f"the policy returned an action of shape {action.shape}; the env's "
                        f"action space has shape {action_shape}"
                    )
                action = action.reshape(action_shape)
            obs, _, terminated, truncated, info = env.step(action)
            buffer[t] = obs[sensor]
            poses[t] = info["robot_pose"]
            blocked += bool(info.get("blocked", False))
            if (terminated or truncated) and t < n_steps - 1:
                raise ValueError(
                    f"the episode ended after {t + 1} of n_steps={n_steps} moves "
                    f"({'terminated' if terminated else 'truncated'}); n_steps must not exceed "
                    "the env's max_episode_steps"
                )
        meta = {
            "env_id": getattr(spec, "id", None),
            "env_kwargs": _json_safe(getattr(spec, "kwargs", None)),
            "seed": seed,
            "policy": _policy_name(pol),
            "policy_seed": _policy_seed(seed),
            "n_steps": n_steps,
            "sensor": sensor,
            "blocked_moves": int(blocked),
        }
        return History(
            sensor=sensor,
            matrix=_steps_to_matrix(buffer, sensor),
            robot_poses=poses,
            meta=meta,
            **truth,
        )
    finally:
        if owned:
            env.close()


def _batched_actions(action: Any, space: Any, batch: int) -> np.ndarray:
    shape = (batch, *tuple(space.shape or ()))
    out = np.asarray(action, dtype=space.dtype)
    if out.shape == shape:
        return out
    if out.size == int(np.prod(shape, dtype=int)):
        return out.reshape(shape)
    raise ValueError(
        f"the policy returned actions of shape {out.shape} for {batch} sub-environments; a policy "
        f"used with a vector env must answer a batched observation with shape {shape}"
    )


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

    from lfmdr_gym.policies import PredictPolicy, as_policy

    n_steps = _check_n_steps(n_steps)
    seed = _check_seed(seed)
    if isinstance(n_episodes, bool) or not isinstance(n_episodes, int) or n_episodes < 1:
        raise ValueError(f"n_episodes must be a positive integer, got {n_episodes!r}")
    if not hasattr(envs, "num_envs") or not hasattr(envs, "single_action_space"):
        raise ValueError(f"envs must be a gymnasium VectorEnv, got {type(envs).__name__}")
    pol = as_policy(policy)
    batch = int(envs.num_envs)
    mode = AutoresetMode(envs.metadata.get("autoreset_mode", AutoresetMode.NEXT_STEP))
    spec = getattr(envs, "spec", None)
    # make_vec keeps the registered limit in spec.max_episode_steps and an override in its kwargs
    limit = (getattr(spec, "kwargs", None) or {}).get(
        "max_episode_steps", getattr(spec, "max_episode_steps", None)
    )
    if limit is not None and n_steps > limit:
        raise ValueError(
            f"n_steps={n_steps} exceeds the sub-envs' max_episode_steps={limit}: every episode "
            "would be truncated first"
        )

    obs, info = envs.reset(seed=seed)
    sensor = _sensor_key(obs)
    _reset_policy(pol, seed)
    sample = np.asarray(obs[sensor])
    buffer = np.empty((batch, n_episodes, n_steps, *sample.shape[1:]), dtype=sample.dtype)
    poses = np.empty((batch, n_episodes, n_steps, 3), dtype=np.float64)
    blocked = np.zeros((batch, n_episodes), dtype=np.int64)
    truths: list[list[dict[str, np.ndarray]]] = [[_truth(info, i)] for i in range(batch)]
    count = np.zeros(batch, dtype=np.int64)  # moves recorded in the current episode
    episode = np.zeros(batch, dtype=np.int64)  # index of the current episode
    pending = np.zeros(batch, dtype=bool)  # NEXT_STEP: this sub-env's next step is a reset
    starts = np.ones(batch, dtype=bool)  # episode_start flags for SB3-style policies

    def record(rows: np.ndarray, observed: np.ndarray, step_info: dict[str, Any]) -> None:
        for i in rows:
            if episode[i] >= n_episodes or count[i] >= n_steps:
                continue  # finished, or moves past n_steps: run, not recorded
            buffer[i, episode[i], count[i]] = observed[i]
            poses[i, episode[i], count[i]] = step_info["robot_pose"][i]
            if "blocked" in step_info:
                blocked[i, episode[i]] += bool(step_info["blocked"][i])
            count[i] += 1

    def new_episode(rows: np.ndarray, reset_info: dict[str, Any]) -> None:
        for i in rows:
            if count[i] < n_steps and episode[i] < n_episodes:
                raise ValueError(
                    f"sub-env {i}'s episode {episode[i]} ended after {count[i]} of "
                    f"n_steps={n_steps} moves; n_steps must not exceed max_episode_steps"
                )
            episode[i] += 1
            count[i] = 0
            starts[i] = True
            if episode[i] < n_episodes:
                truths[i].append(_truth(reset_info, i))

    def finished() -> bool:
        last_done = (episode == n_episodes - 1) & (count >= n_steps)
        return bool((last_done | (episode >= n_episodes)).all())

    while not finished():
        if isinstance(pol, PredictPolicy):
            action = pol(obs, episode_start=starts.copy())
        else:
            action = pol(obs)
        starts[:] = False
        obs, _, terminated, truncated, info = envs.step(
            _batched_actions(action, envs.single_action_space, batch)
        )
        done = np.asarray(terminated) | np.asarray(truncated)
        if mode == AutoresetMode.NEXT_STEP:
            moved = np.flatnonzero(~pending)
            record(moved, np.asarray(obs[sensor]), info)
            new_episode(np.flatnonzero(pending), info)  # these rows were reset steps
            pending = done & ~pending
        elif mode == AutoresetMode.SAME_STEP:
            observed = np.asarray(obs[sensor]).copy()
            step_info = {k: np.array(v, copy=True) for k, v in info.items()
                         if k in ("robot_pose", "blocked")}
            ended = np.flatnonzero(done)
            for i in ended:  # the move's own observation and info, before the autoreset
                observed[i] = info["final_obs"][i][sensor]
                final_info = info["final_info"]
                step_info["robot_pose"][i] = final_info["robot_pose"][i]
                if "blocked" in step_info:
                    step_info["blocked"][i] = final_info["blocked"][i]
            record(np.arange(batch), observed, step_info)
            new_episode(ended, info)
        else:  # DISABLED: the collector resets finished sub-envs itself
            record(np.arange(batch), np.asarray(obs[sensor]), info)
            if done.any():
                obs, reset_info = envs.reset(options={"reset_mask": done})
                new_episode(np.flatnonzero(done), reset_info)

    meta_base = {
        "env_id": getattr(spec, "id", None),
        "env_kwargs": _json_safe(getattr(spec, "kwargs", None)),
        "policy": _policy_name(pol),
        "policy_seed": _policy_seed(seed),
        "n_steps": n_steps,
        "sensor": sensor,
        "num_envs": batch,
        "autoreset_mode": mode.value,
    }
    histories = []
    for i in range(batch):
        for e in range(n_episodes):
            meta = dict(meta_base, sub_env=i, episode=e, blocked_moves=int(blocked[i, e]))
            meta["seed"] = (seed + i) if (seed is not None and e == 0) else None
            if seed is not None:
                meta["first_episode_seed"] = seed + i
            histories.append(
                History(
                    sensor=sensor,
                    matrix=_steps_to_matrix(buffer[i, e], sensor),
                    robot_poses=poses[i, e],
                    meta=meta,
                    **truths[i][e],
                )
            )
    return histories
