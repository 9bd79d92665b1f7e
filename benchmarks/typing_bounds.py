"""The fewest typing steps each task allows, beside a pose-aware script, the touch-only optimum and the
paper's Table III.

For each task and each typing protocol (the paper's text: no reset between
keys; the released code: a reset per key), on the dataset backend:

* **bound**: :func:`tactile_braille.evaluation.bounds.typing_bound`, the
  fewest steps any policy can type the paper's sequences in, even one that
  knows the sensor's pose and the key layout. With no reset it is for the
  start poses of the typing evaluation's seed (0 unless --seeds); with a reset
  per key it is the expectation over random starts.
* **pose script**: ``PoseScript`` (tactile_braille.envs.oracle), which goes
  straight for the goal key's centre and presses on the step that lands there.
* **touch-only optimum** (discrete tasks): the fewest steps expected of a
  policy that knows only what it has felt (``touch_optimum``; a lower bound
  with no reset).

Run: python benchmarks/typing_bounds.py [--seeds 1]
"""

from __future__ import annotations

import argparse

import gymnasium as gym
import numpy as np

import tactile_braille  # noqa: F401 - registers the environments
from tactile_braille.envs.oracle import PoseScript
from tactile_braille.evaluation.bounds import typing_bound
from tactile_braille.evaluation.protocol import paper_sequences, type_sequences
from tactile_braille.evaluation.report import PAPER_TABLE
from tactile_braille.evaluation.scoring import touch_optimum

TASKS = ("DiscreteArrows-v0", "DiscreteAlphabet-v0", "ContinuousArrows-v0", "ContinuousAlphabet-v0")


def _cell(values: list[float]) -> str:
    low, high = min(values), max(values)
    return f"{low:.0f}" if round(low) == round(high) else f"{np.mean(values):.0f} ({low:.0f}-{high:.0f})"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=1, help="typing seeds (start poses) per protocol")
    args = parser.parse_args()
    print("| task | bound, no reset | pose script, no reset | touch-only, no reset (>=) "
          "| bound, reset per key (expected) | pose script, reset per key "
          "| paper's Table III steps |")  # fmt: skip
    print("|---|---|---|---|---|---|---|")
    for task in TASKS:
        env = gym.make(f"tactile_braille/{task}")
        keys = env.unwrapped.task.keys
        sequences = paper_sequences(keys)
        script = PoseScript(env)
        cells = []
        for protocol in ("paper", "released"):
            seeds = range(args.seeds)
            bounds = [typing_bound(task, sequences, protocol, seed) for seed in seeds]
            steps = [type_sequences(script, env, sequences, seed, protocol).total_steps for seed in seeds]
            cells += [_cell(bounds), _cell(steps)]
            if protocol == "paper":
                continuous = env.unwrapped.task.continuous
                cells.append("-" if continuous else f"{touch_optimum(keys, sequences, 'paper'):.0f}")
        paper = ", ".join(f"{v[0]} ({algo})" for (platform, t, algo), v in PAPER_TABLE.items()
                          if platform == "sim" and t == task)  # fmt: skip
        print(f"| {task} | " + " | ".join(cells) + f" | {paper} |")


if __name__ == "__main__":
    main()
