"""Stable-Baselines3 with Hindsight Experience Replay on a braille task, scored by the benchmark.

A baseline from the library most users already have: SB3's DQN (discrete
tasks), SAC or TD3 (continuous tasks) with its ``HerReplayBuffer``, on the
environment exactly as registered (no wrapper, no extra information: the
``tactile`` track). After training, the model types the paper's sequences
through ``tactile_braille.evaluation.evaluate_policy`` and the results file
is written for the leaderboard.

    python examples/sb3_her.py DiscreteArrows-v0 dqn --steps 6000 --seed 0 \\
        --output results/leaderboard/sb3/DiscreteArrows-v0__dqn__0.json

Hyperparameters: SB3's defaults, except where a default cannot work within
these budgets (stated below, the same for every task): the replay holds the
whole run, learning starts after 1,000 steps, DQN's target network follows
every 500 steps and its exploration decays over the first 30 % of the run
(trained every step), and SAC and TD3 learn from batches of 64 with one
image network shared by actor and critics (SB3's default, 256 with three
networks, runs at about a second per step on one CPU thread).
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import gymnasium as gym
import torch
from stable_baselines3 import DQN, SAC, TD3, HerReplayBuffer

import tactile_braille  # noqa: F401 - registers the environments
from tactile_braille.evaluation.results import make_result, write_result
from tactile_braille.evaluation.scoring import evaluate_policy

ALGORITHMS = {"dqn": DQN, "sac": SAC, "td3": TD3}
SHARED_IMAGE_NETWORK = {"batch_size": 64, "policy_kwargs": {"share_features_extractor": True}}
SETTINGS = {
    "dqn": {"target_update_interval": 500, "exploration_fraction": 0.3, "train_freq": 1},
    "sac": SHARED_IMAGE_NETWORK,
    "td3": SHARED_IMAGE_NETWORK,
}
"""What departs from SB3's defaults, per algorithm (besides the replay size and learning start)."""


def train(task: str, algo: str, steps: int, seed: int, dataset=None, learning_starts: int = 1_000):
    """An SB3 model trained with HER for ``steps`` environment steps; returns (model, seconds)."""
    env = gym.make(f"tactile_braille/{task}", **({"dataset": dataset} if dataset else {}))
    model = ALGORITHMS[algo](
        "MultiInputPolicy", env, replay_buffer_class=HerReplayBuffer,
        replay_buffer_kwargs={"n_sampled_goal": 4, "goal_selection_strategy": "future"},
        buffer_size=max(steps, 1), learning_starts=min(learning_starts, steps), seed=seed, device="cpu",
        verbose=0, **SETTINGS[algo],
    )  # fmt: skip
    start = time.perf_counter()
    model.learn(steps)
    return model, time.perf_counter() - start


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("task", help="e.g. DiscreteArrows-v0")
    parser.add_argument("algo", choices=sorted(ALGORITHMS))
    parser.add_argument("--steps", type=int, required=True, help="environment steps to train")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--output", type=Path, required=True, help="the results file to write")
    parser.add_argument("--dataset", type=Path, help="the dataset backend's file (default: the cached one)")
    parser.add_argument("--learning-starts", type=int, default=1_000)
    parser.add_argument("--threads", type=int, default=1)
    parser.add_argument("--save", type=Path, help="also save the model (an SB3 zip)")
    args = parser.parse_args(argv)
    if args.output.exists():
        parser.error(f"{args.output} exists; choose another name")
    if args.learning_starts <= 25:  # HER samples from finished episodes only
        parser.error("--learning-starts must exceed an episode's 25 steps")
    torch.set_num_threads(args.threads)

    model, seconds = train(args.task, args.algo, args.steps, args.seed, args.dataset, args.learning_starts)
    if args.save is not None:
        model.save(args.save)
    report = evaluate_policy(
        lambda observation: model.predict(observation, deterministic=True)[0], args.task, dataset=args.dataset
    )
    method = f"SB3 {args.algo.upper()} + HER ({seconds / 60:.0f} min on {args.threads} CPU thread(s))"
    result = make_result(
        report, method=f"SB3 {args.algo.upper()} + HER", seed=args.seed, env_steps=args.steps,
        notes=f"examples/sb3_her.py; {method}",
    )  # fmt: skip
    write_result(result, args.output)
    print(f"{args.task} {args.algo} seed {args.seed}: accuracy {report.accuracy:.3f}, "
          f"{report.total_steps} steps ({args.steps} env steps trained in {seconds / 60:.1f} min); "
          f"wrote {args.output}")  # fmt: skip
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
