"""Return and episode length of a random policy and of the scripted oracle, every task and backend.

The oracle knows the true sensor pose (tactile_braille.envs.oracle): a return
near 1.0 proves each task solvable in our simulation; the random policy is the
floor. Also writes an oracle episode GIF per task with --gif-dir.

    python benchmarks/policies.py [--episodes 100] [--gif-dir docs/images]
"""

from __future__ import annotations

import argparse
from pathlib import Path

import gymnasium as gym
import numpy as np

import tactile_braille  # noqa: F401 - registers the environments
from tactile_braille.envs import ENV_IDS
from tactile_braille.envs.oracle import oracle_action
from tactile_braille.envs.rendering import save_gif


def run(env, policy: str, episodes: int, frames: list | None = None) -> tuple[float, float]:
    returns, lengths = [], []
    env.action_space.seed(0)
    for episode in range(episodes):
        env.reset(seed=episode)
        total, steps, done = 0.0, 0, False
        if frames is not None and episode == 0:
            frames.append(env.render())
        while not done:
            action = oracle_action(env) if policy == "oracle" else env.action_space.sample()
            _, reward, terminated, truncated, _ = env.step(action)
            total, steps, done = total + reward, steps + 1, terminated or truncated
            if frames is not None and episode == 0:
                frames.append(env.render())
        returns.append(total)
        lengths.append(steps)
    return float(np.mean(returns)), float(np.mean(lengths))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--episodes", type=int, default=100)
    parser.add_argument("--gif-dir", type=Path, default=None)
    args = parser.parse_args()
    print(f"{'environment':40s} {'backend':8s} {'random return':>14s} {'length':>7s} "
          f"{'oracle return':>14s} {'length':>7s}")  # fmt: skip
    for env_id in ENV_IDS:
        for backend in ("dataset", "render"):
            render_mode = "rgb_array" if args.gif_dir and backend == "render" else None
            env = gym.make(env_id, backend=backend, render_mode=render_mode)
            random_return, random_length = run(env, "random", args.episodes)
            frames: list | None = [] if render_mode else None
            oracle_return, oracle_length = run(env, "oracle", args.episodes, frames)
            print(f"{env_id:40s} {backend:8s} {random_return:14.2f} {random_length:7.1f} "
                  f"{oracle_return:14.2f} {oracle_length:7.1f}")  # fmt: skip
            if frames:
                name = env_id.split("/")[1].split("-")[0]
                print(f"  wrote {save_gif(frames, args.gif_dir / f'episode_{name}.gif', fps=2)}")


if __name__ == "__main__":
    main()
