"""Train the reinforcement-learned exploration policy: SB3 PPO on the coverage reward, on CPU.

Needs the ``rl`` extra: ``pip install -e ".[rl]"`` (it pins torch 2.13.0, whose CPU build is
what our machines resolve it to; elsewhere install a CPU torch first). It trains PPO (an MLP actor-critic, tanh, 64 x 64) on
:class:`lfmdr_gym.wrappers.MappingRewardWrapper` around both sensors' envs (episodes of 500
steps, fresh layouts each), then exports the actor to a small ``.npz`` that
:class:`lfmdr_gym.exploration.rl.MLPExplorationPolicy` runs in numpy — the registered ``"rl"``
policy reads the copy shipped in ``lfmdr_gym/models/``. Finally it checks that the numpy
forward pass gives SB3's deterministic actions on the last observations.

    python examples/train_rl_policy.py --out lfmdr_gym/models/rl_policy.npz   # the shipped model

300,000 steps take about 4 minutes on an idle machine (more under other jobs' load); seed 0 and
the defaults made the shipped model (training is deterministic: a rerun gives the same weights).

    python examples/train_rl_policy.py --reward pose --out /tmp/pose.npz  # ground-truth reward
    python examples/train_rl_policy.py --timesteps 512 --out /tmp/m.npz   # smoke test
"""

from __future__ import annotations

import argparse
import os
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np


@dataclass(frozen=True)
class TrainConfig:
    """What a training run is fixed by (CleanRL-style: one frozen record)."""

    timesteps: int = 300_000
    n_envs: int = 4
    episode_steps: int = 500
    reward: str = "odometry"
    seed: int = 0
    n_steps: int = 512  # PPO rollout per env
    batch_size: int = 256
    learning_rate: float = 3e-4
    gamma: float = 0.95
    ent_coef: float = 0.0
    presence: bool = True  # the two presence figures in the observation


def make_vec_env(cfg: TrainConfig):
    """``n_envs`` wrapped envs, alternating the visibility and the bearing sensor."""
    import gymnasium as gym
    from stable_baselines3.common.monitor import Monitor
    from stable_baselines3.common.vec_env import DummyVecEnv

    import lfmdr_gym
    from lfmdr_gym.wrappers import MappingRewardWrapper

    ids = [lfmdr_gym.env_id_for(s) for s in ("visibility", "bearing")]

    def factory(k: int):
        return lambda: Monitor(MappingRewardWrapper(
            gym.make(ids[k % 2], max_episode_steps=cfg.episode_steps), reward=cfg.reward,
            presence=cfg.presence))

    venv = DummyVecEnv([factory(k) for k in range(cfg.n_envs)])
    venv.seed(cfg.seed)
    return venv


def train(cfg: TrainConfig, out: str | os.PathLike, *, verbose: int = 0):
    """Train, export the actor to ``out`` and return ``(model, path, max_abs_action_diff)``."""
    try:
        import torch
        from stable_baselines3 import PPO
    except ImportError as exc:
        raise SystemExit("training needs the rl extra: pip install -e '.[rl]'") from exc
    from lfmdr_gym.exploration.rl import export_sb3, load_mlp, mlp_forward

    torch.set_num_threads(1)
    venv = make_vec_env(cfg)
    model = PPO(
        "MlpPolicy", venv, n_steps=min(cfg.n_steps, max(cfg.timesteps // cfg.n_envs, 8)),
        batch_size=cfg.batch_size, learning_rate=cfg.learning_rate, gamma=cfg.gamma,
        ent_coef=cfg.ent_coef, seed=cfg.seed, device="cpu", verbose=verbose,
        policy_kwargs={"net_arch": {"pi": [64, 64], "vf": [64, 64]}, "activation_fn": torch.nn.Tanh},
    )
    model.learn(total_timesteps=cfg.timesteps)
    view_config = venv.envs[0].get_wrapper_attr("view").config
    path = export_sb3(model, out, view_config)
    # The numpy forward pass must reproduce SB3's deterministic action.
    obs = np.stack([venv.envs[k].get_wrapper_attr("view").features() for k in range(cfg.n_envs)])
    sb3_action, _ = model.predict(obs, deterministic=True)
    layers, _ = load_mlp(path)
    diff = float(np.max(np.abs(mlp_forward(layers, obs) - sb3_action)))
    venv.close()
    return model, path, diff


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--timesteps", type=int, default=TrainConfig.timesteps)
    ap.add_argument("--n-envs", type=int, default=TrainConfig.n_envs)
    ap.add_argument("--episode-steps", type=int, default=TrainConfig.episode_steps)
    ap.add_argument("--reward", default=TrainConfig.reward, choices=("odometry", "pose"))
    ap.add_argument("--seed", type=int, default=TrainConfig.seed)
    ap.add_argument("--no-presence", action="store_true",
                    help="leave the presence figures out of the agent's observation")
    ap.add_argument("--out", default="rl_policy.npz", help="model file to write (.npz)")
    ap.add_argument("--verbose", type=int, default=0)
    args = ap.parse_args(argv)
    if args.timesteps < 1 or args.n_envs < 1 or args.episode_steps < 1:
        ap.error("--timesteps, --n-envs and --episode-steps must be positive")
    os.environ.setdefault("OMP_NUM_THREADS", "1")
    cfg = TrainConfig(timesteps=args.timesteps, n_envs=args.n_envs,
                      episode_steps=args.episode_steps, reward=args.reward, seed=args.seed,
                      presence=not args.no_presence)
    start = time.perf_counter()
    _, path, diff = train(cfg, args.out, verbose=args.verbose)
    print(f"trained {cfg.timesteps} steps in {time.perf_counter() - start:.0f} s; wrote "
          f"{path} ({Path(path).stat().st_size} bytes); numpy vs SB3 action: max |diff| {diff:.2e}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
