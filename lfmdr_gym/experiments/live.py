"""Live maps: one episode mapped online as the robot moves, saved as an animated GIF.

Each frame puts the arena as the environment renders it (``render_mode="rgb_array"``) beside the
map :class:`mappers.OnlineMapper` holds at that step (estimates in blue, joined to the true
objects by red lines; the map panel widens beyond the arena's walls when an estimate falls
outside them, so no estimate is cut off). The mapper gets the new steps' sensor columns and the
anchors, nothing else; the truth only scores and draws the map. The GIF is written with
matplotlib's ``PillowWriter`` (the ``plots`` extra). :func:`run_online` (``lfmdr run
--online``) also writes the episode's history, the online scores and the final map.
"""

from __future__ import annotations

import csv
import os
import warnings
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from lfmdr_gym.atomic import atomic_write

__all__ = ["OnlineRun", "online_episode", "run_online", "save_gif"]

# margin around the farthest estimate when the map panel must widen beyond the arena [m]
_VIEW_MARGIN = 0.1


def online_episode(env_id: str, steps: int, *, seed: int | None = 0, policy: str = "random-walk",
                   method: str | None = None, params: dict[str, Any] | None = None,
                   every: int = 10, frame_every: int = 20, size: int = 240,
                   env_kwargs: dict[str, Any] | None = None):
    """Run one episode of ``env_id`` (with the env keywords ``env_kwargs``) with the policy
    named ``policy``, updating an online map every ``every`` steps; a frame (arena | map) every
    ``frame_every`` steps. An env that reports what it measured (``"observed"``, imperfect
    sensing) gives a masked history, mapped by the masked default (or ``method``).

    Returns ``(frames, rows, final_map)``: the (H, 2W, 3) uint8 frames, one dict per update
    (``n_steps``; ``mpe``: mean position error of the non-anchor objects mapped so far [m], NaN
    while none is; ``mapped``, anchors included; ``note``: why there is no map yet, else "")
    and the last :class:`mappers.Map`. :func:`run_online` also gives the episode's History.
    """
    frames, rows, final, _ = _online(env_id, steps, seed=seed, policy=policy, method=method,
                                     params=params, every=every, frame_every=frame_every,
                                     size=size, env_kwargs=env_kwargs)
    return frames, rows, final


def _resized(image: np.ndarray, size: int) -> np.ndarray:
    """A square RGB image at ``size`` pixels: averaged over blocks when the size divides (a
    one-pixel wall stays visible), else the nearest pixel."""
    n = image.shape[0]
    if n == size:
        return image
    if n % size == 0:
        k = n // size
        blocks = image.reshape(size, k, size, k, 3).astype(np.float64)
        return np.rint(blocks.mean(axis=(1, 3))).astype(np.uint8)
    idx = np.arange(size) * n // size
    return image[idx][:, idx]


def _no_map_reason(current: Any) -> str:
    """Why an online map places no object but the anchors (its warnings say what the mapper
    found; with none, nothing has been sensed that could be placed)."""
    if current is not None and current.warnings:
        return "; ".join(current.warnings)
    return "no object other than the anchors has been sensed yet"


def _online(env_id, steps, *, seed, policy, method, params, every, frame_every, size, env_kwargs):
    """:func:`online_episode`, and the episode recorded as a History."""
    import mappers
    from lfmdr_gym import ENV_IDS
    from lfmdr_gym.checks import check_int
    from lfmdr_gym.experiments.episodes import make_env
    from lfmdr_gym.exploration import POLICIES, as_policy
    from lfmdr_gym.histories.history import History
    from lfmdr_gym.render import draw_map
    from mappers.core.sensors import FUSED_SENSORS

    if ENV_IDS.get(env_id) in FUSED_SENSORS:
        raise ValueError(f"online mapping (mappers.OnlineMapper) takes one sensor's histories; "
                         f"{env_id} observes {ENV_IDS[env_id]} (fused sensors): map its episode "
                         "offline (lfmdr run without --online)")

    for name, value in (("steps", steps), ("every", every), ("frame_every", frame_every)):
        check_int(name, value, low=1)
    if policy not in POLICIES:
        raise ValueError(f"unknown policy {policy!r}; choose from {list(POLICIES)}")
    env = make_env(env_id, steps, {**dict(env_kwargs or {}), "render_mode": "rgb_array"})
    try:
        obs, info = env.reset(seed=seed)
        world = env.unwrapped.world
        sensor = env.unwrapped.sensor
        truth = np.asarray(info["object_positions"], dtype=float)
        anchors = np.asarray(info["anchor_ids"])
        agent = as_policy(POLICIES[policy](env, seed=seed))
        agent.reset(seed=seed)
        mapper = mappers.OnlineMapper(anchors, truth[anchors], sensor=sensor, method=method,
                                      **dict(params or {}))
        keep = np.setdiff1d(np.arange(len(truth)), anchors)
        frames, rows, batch, seen, current = [], [], [], [], None
        columns, flags, poses, blocked = [], [], [], 0  # the whole episode, for its History
        for t in range(1, steps + 1):
            obs, _, _, _, info = env.step(agent(obs))
            batch.append(np.asarray(obs[sensor], dtype=float).reshape(len(truth), -1))
            columns.append(batch[-1])
            poses.append(np.asarray(info["robot_pose"], dtype=float))
            blocked += bool(info.get("blocked", False))
            if "observed" in obs:  # one flag per object and step covers the step's columns
                step_flags = np.asarray(obs["observed"], dtype=bool)[:, None]
                seen.append(np.repeat(step_flags, batch[-1].shape[1], axis=1))
                flags.append(seen[-1])
            if t % every == 0 or t == steps:
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore")
                    current = mapper.update(np.concatenate(batch, axis=1),
                                            np.concatenate(seen, axis=1) if seen else None)
                batch, seen = [], []
                ok = keep[np.all(np.isfinite(current.positions[keep]), axis=1)]
                mpe = (mappers.mean_position_error(current.positions[ok], truth[ok])
                       if ok.size else float("nan"))
                rows.append({"n_steps": t, "mpe": mpe, "mapped": int(ok.size + anchors.size),
                             "note": "" if ok.size else _no_map_reason(current)})
            if t % frame_every == 0 or t == steps:
                est = current.positions if current is not None else np.full_like(truth, np.nan)
                placed = est[np.all(np.isfinite(est), axis=1)]
                reach = float(np.abs(placed).max()) + _VIEW_MARGIN if placed.size else 0.0
                picture = draw_map(arena_half=world.arena_half, estimates=est, truth=truth,
                                   object_radius=world.object_radius, anchor_ids=anchors,
                                   size=size, view_half=max(world.arena_half, reach),
                                   covariances=getattr(current, "covariances", None))
                frames.append((t, np.concatenate([_resized(env.render(), size), picture], axis=1)))
    finally:
        env.close()
    history = History(
        sensor=sensor, matrix=np.concatenate(columns, axis=1),
        mask=np.concatenate(flags, axis=1) if flags else None,
        object_positions=truth, anchor_ids=anchors, anchor_positions=truth[anchors],
        robot_poses=np.asarray(poses),
        meta={"env_id": env_id, "seed": seed, "policy": policy, "n_steps": int(steps),
              "sensor": sensor, "online": True, "blocked_moves": int(blocked)},
    )
    return frames, rows, current, history


@dataclass(frozen=True, eq=False)
class OnlineRun:
    """What :func:`run_online` did.

    Attributes:
        method: the online map's method label; params: its parameters.
        rows: one dict per update (see :func:`online_episode`).
        checkpoints: the rows at the checkpoints (``every``, and the last step).
        map: the final online :class:`mappers.Map`; history: the episode as a History.
        written: the files written into ``out``, in order.
    """

    method: str
    params: dict[str, Any]
    rows: list[dict[str, Any]]
    checkpoints: list[dict[str, Any]]
    map: Any
    history: Any
    written: tuple[Path, ...]


def run_online(
    env_id: str,
    steps: int,
    method: str | None = None,
    *,
    out: str | os.PathLike,
    seed: int | None = 0,
    every: int | None = None,
    params: Iterable[str] | Mapping[str, Any] | None = None,
    env_kwargs: Mapping[str, Any] | None = None,
    policy: str = "random-walk",
    update_every: int = 10,
) -> OnlineRun:
    """One episode mapped online (``lfmdr run --online``), with its files written into ``out``:
    ``history.npz`` (the episode), ``scores.csv`` (one row per update: ``n_steps``, ``method``,
    ``param``, ``mpe_nonanchor``, ``mapped`` (anchors included), ``note``: why there is no
    map yet), ``map.csv`` and ``map.png`` (the final online map, its warnings below the plot)
    and ``live.gif`` (the map growing beside the robot; needs matplotlib). ``every``: the
    checkpoints reported (as ``lfmdr run``'s); the map is updated every ``update_every``
    steps."""
    from lfmdr_gym.experiments.env_settings import check_env_kwargs
    from lfmdr_gym.experiments.mapping import _sensor_of, _write_map, checkpoints_for
    from lfmdr_gym.experiments.params import method_label, param_label, user_params
    from lfmdr_gym.experiments.store import ensure_writable_dir
    from mappers import resolve_method

    sensor = _sensor_of(env_id)
    points = set(checkpoints_for(steps, every, sensor))
    out = ensure_writable_dir(out)
    env_kwargs, masked = check_env_kwargs(sensor, env_kwargs)
    label = resolve_method(method, sensor, masked=masked).label
    chosen = user_params(label, params)
    frames, rows, final, history = _online(
        env_id, steps, seed=seed, policy=policy, method=method, params=chosen,
        every=update_every, frame_every=max(steps // 50, 1), size=240, env_kwargs=env_kwargs)
    history = history.replace(meta={**history.meta, "env_kwargs": dict(env_kwargs)})
    written = [history.save(out / "history.npz")]
    with atomic_write(out / "scores.csv") as fh:
        writer = csv.writer(fh)
        writer.writerow(["n_steps", "method", "param", "mpe_nonanchor", "mapped", "note"])
        for r in rows:
            writer.writerow([r["n_steps"], label, param_label(chosen), f"{r['mpe']:.6g}",
                             r["mapped"], r["note"]])
    written.append(out / "scores.csv")
    last = rows[-1]
    score = (f"MPE non-anchor {last['mpe']:.3f} m" if np.isfinite(last["mpe"])
             else "no map yet")
    figure = _write_map(out, final.positions, history,
                        f"{env_id}, online {method_label(label, chosen)}, N={steps}: {score}",
                        notes=final.warnings)
    written += [out / "map.csv", figure]
    written.append(save_gif(frames, rows, out / "live.gif", title=f"{env_id} ({policy})"))
    return OnlineRun(method=label, params=chosen, rows=rows,
                     checkpoints=[r for r in rows if r["n_steps"] in points], map=final,
                     history=history, written=tuple(written))


def save_gif(frames, rows, path: str | os.PathLike, *, title: str = "", fps: int = 8) -> Path:
    """Write the frames of :func:`online_episode` as an animated GIF (atomically), each with
    its step count and the online map's error so far in the title."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.animation import FuncAnimation, PillowWriter

    path = Path(path)
    if path.suffix.lower() != ".gif":
        raise ValueError(f"the animation file must end in .gif, got {path.name!r}")
    if not frames:
        raise ValueError("no frames to write")
    mpe = {r["n_steps"]: r["mpe"] for r in rows}
    h, w = frames[0][1].shape[:2]
    fig = plt.figure(figsize=(w / 80, h / 80 + 0.35), dpi=80)
    ax = fig.add_axes((0, 0, 1, h / (h + 28)))
    ax.set_axis_off()
    image = ax.imshow(frames[0][1])
    label = fig.text(0.5, 1 - 14 / (h + 28), "", ha="center", va="center", fontsize=9)

    def show(k):
        t, frame = frames[k]
        image.set_data(frame)
        err = mpe.get(t, float("nan"))
        score = f"online map MPE {err:.3f} m" if np.isfinite(err) else "no online map yet"
        label.set_text(f"{title}  step {t}   {score}")
        return image, label

    anim = FuncAnimation(fig, show, frames=len(frames), blit=False)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.stem}.tmp.gif")
    try:
        anim.save(tmp, writer=PillowWriter(fps=fps))
        os.replace(tmp, path)
    finally:
        plt.close(fig)
        if tmp.exists():
            tmp.unlink()
    return path
