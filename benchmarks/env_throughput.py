"""Environment steps per second for every task and backend, single and vectorised, in one run.

Single environments are made with ``gym.make`` (with the registry's wrappers)
and driven by random actions, resetting at episode ends; the vectorised
environment steps 64 dataset-backend environments at once, and 64 render-backend
ones with the batched renderer on the CPU (``render_device="cpu"``) and tap by
tap (``render_device=None``). Targets on one core: dataset backend >= 20,000
steps/s single and >= 200,000 steps/s vectorised; render backend >= 1,000 steps/s.

    python benchmarks/env_throughput.py [--seconds 2]
"""

from __future__ import annotations

import argparse
import os
import time

os.environ.setdefault("OMP_NUM_THREADS", "1")

import cv2
import gymnasium as gym
import torch

import tactile_braille
from tactile_braille.envs import ENV_IDS


def single_rate(env_id: str, backend: str, seconds: float) -> float:
    env = gym.make(env_id, backend=backend)
    env.reset(seed=0)
    env.action_space.seed(0)
    actions = [env.action_space.sample() for _ in range(4096)]
    steps, start = 0, time.perf_counter()
    while time.perf_counter() - start < seconds:
        for action in actions[:256]:
            _, _, terminated, truncated, _ = env.step(action)
            if terminated or truncated:
                env.reset()
        steps += 256
        actions = actions[256:] + actions[:256]
    return steps / (time.perf_counter() - start)


def vector_rate(env_id: str, num_envs: int, seconds: float, **options) -> float:
    envs = gym.make_vec(env_id, num_envs=num_envs, vectorization_mode="vector_entry_point", **options)
    envs.reset(seed=0)
    envs.action_space.seed(0)
    batches = [envs.action_space.sample() for _ in range(64)]
    steps, start = 0, time.perf_counter()
    while time.perf_counter() - start < seconds:
        for batch in batches:
            envs.step(batch)
        steps += len(batches) * num_envs
    return steps / (time.perf_counter() - start)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=2.0)
    parser.add_argument("--num-envs", type=int, default=64)
    args = parser.parse_args()
    cv2.setNumThreads(1)
    print(f"tactile_braille {tactile_braille.__version__}, one core, random actions, steps per second")
    torch.set_num_threads(1)
    vector = f"vector x{args.num_envs}"
    print(f"{'environment':40s} {'dataset':>10s} {'render':>10s} {vector:>12s} "
          f"{'render ' + vector + ' batched':>24s} {'tap by tap':>12s}")  # fmt: skip
    for env_id in ENV_IDS:
        dataset = single_rate(env_id, "dataset", args.seconds)
        render = single_rate(env_id, "render", args.seconds)
        batch = vector_rate(env_id, args.num_envs, args.seconds)
        batched = vector_rate(env_id, args.num_envs, args.seconds, backend="render", render_device="cpu")
        tapped = vector_rate(env_id, args.num_envs, args.seconds, backend="render", render_device=None)
        print(f"{env_id:40s} {dataset:10.0f} {render:10.0f} {batch:12.0f} {batched:24.0f} {tapped:12.0f}")
    print("targets: dataset >= 20,000; render >= 1,000; vector >= 200,000")


if __name__ == "__main__":
    main()
