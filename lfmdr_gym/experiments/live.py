"""Live maps: one episode mapped online as the robot moves, saved as an animated GIF.

Each frame puts the arena as the environment renders it (``render_mode="rgb_array"``) beside the
map :class:`mappers.OnlineMapper` holds at that step (estimates in blue, joined to the true
objects by red lines). The mapper gets the new steps' sensor columns and the anchors, nothing
else; the truth only scores and draws the map. The GIF is written with matplotlib's
``PillowWriter`` (the ``plots`` extra).
"""

from __future__ import annotations

import os
import warnings
from pathlib import Path
from typing import Any

import numpy as np

__all__ = ["online_episode", "save_gif"]


def online_episode(env_id: str, steps: int, *, seed: int | None = 0, policy: str = "random-walk",
                   method: str | None = None, params: dict[str, Any] | None = None,
                   every: int = 10, frame_every: int = 20, size: int = 240,
                   env_kwargs: dict[str, Any] | None = None):
    """Run one episode of ``env_id`` (with the env keywords ``env_kwargs``) with the policy
    named ``policy``, updating an online map every ``every`` steps; a frame (arena | map) every
    ``frame_every`` steps. An env that reports what it measured (``"observed"``, imperfect
    sensing) gives a masked history, mapped by the masked default (or ``method``).

    Returns ``(frames, rows, final_map)``: the (H, 2W, 3) uint8 frames, one dict per update
    (``n_steps``, ``mpe``: mean position error of the non-anchor objects mapped so far [m],
    ``mapped``) and the last :class:`mappers.Map`.
    """
    import mappers
    from lfmdr_gym import ENV_IDS
    from lfmdr_gym.checks import check_int
    from lfmdr_gym.experiments.episodes import make_env
    from lfmdr_gym.exploration import POLICIES, as_policy
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
        for t in range(1, steps + 1):
            obs, _, _, _, _ = env.step(agent(obs))
            batch.append(np.asarray(obs[sensor], dtype=float).reshape(len(truth), -1))
            if "observed" in obs:  # one flag per object and step covers the step's columns
                flags = np.asarray(obs["observed"], dtype=bool)[:, None]
                seen.append(np.repeat(flags, batch[-1].shape[1], axis=1))
            if t % every == 0 or t == steps:
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore")
                    current = mapper.update(np.concatenate(batch, axis=1),
                                            np.concatenate(seen, axis=1) if seen else None)
                batch, seen = [], []
                ok = keep[np.all(np.isfinite(current.positions[keep]), axis=1)]
                mpe = (mappers.mean_position_error(current.positions[ok], truth[ok])
                       if ok.size else float("nan"))
                rows.append({"n_steps": t, "mpe": mpe, "mapped": int(ok.size + anchors.size)})
            if t % frame_every == 0 or t == steps:
                est = current.positions if current is not None else np.full_like(truth, np.nan)
                picture = draw_map(arena_half=world.arena_half, estimates=est, truth=truth,
                                   object_radius=world.object_radius, anchor_ids=anchors, size=size)
                arena = env.render()
                if arena.shape[0] != size:  # the env draws at its own size: nearest-pixel resize
                    idx = np.arange(size) * arena.shape[0] // size
                    arena = arena[idx][:, idx]
                frames.append((t, np.concatenate([arena, picture], axis=1)))
    finally:
        env.close()
    return frames, rows, current


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
        label.set_text(f"{title}  step {t}   online map MPE {err:.3f} m")
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
