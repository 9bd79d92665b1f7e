"""Which typing protocol did the paper's Table III use? Steps of a pose-aware oracle under both.

The paper's text types each sequence without resetting the sensor between
keys; the released evaluation scripts reset it to a random pose before every
key (docs/evaluation.md). This script types the paper's sequences with an
oracle that knows the sensor's pose (it reads no image: it is a yardstick, not
a baseline) under both protocols, on the dataset backend, and prints its
steps beside the paper's Table III. A learnt policy cannot beat the oracle by
much, so a printed step count below the oracle's under one protocol says that
protocol was not the one used.

The oracle: discrete tasks, the shortest path over the key grid then PRESS;
continuous tasks, a straight move towards the goal key's centre, pressing
(deepest tap) on the step that lands on it, and tapping lightly on the way.

For the discrete tasks it also prints the touch-only optimum: the fewest
steps expected of any policy that knows only what it has felt (a search over
what the sensor may be on: the off-key cells all feel alike), exact over the
uniform random starts. Under no reset, keys after the first start where the
last press left the sensor, taken as known (a lower bound).

Run: python benchmarks/typing_protocols.py [--seeds 5]
"""

from __future__ import annotations

import argparse

import gymnasium as gym
import numpy as np

import tactile_braille  # noqa: F401 - registers the environments
from tactile_braille.envs.oracle import PoseScript
from tactile_braille.evaluation.protocol import paper_sequences, type_sequences
from tactile_braille.evaluation.report import PAPER_TABLE
from tactile_braille.evaluation.scoring import touch_optimum

TASKS = ("DiscreteArrows-v0", "DiscreteAlphabet-v0", "ContinuousArrows-v0", "ContinuousAlphabet-v0")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=5, help="start-pose seeds per protocol")
    args = parser.parse_args()
    print("| task | oracle steps, no reset (paper's text) | oracle steps, reset per key (released code) "
          "| oracle accuracy | paper's Table III steps (algorithms) |")  # fmt: skip
    print("|---|---|---|---|---|")
    for task in TASKS:
        env = gym.make(f"tactile_braille/{task}")
        sequences = paper_sequences(env.unwrapped.task.keys)
        oracle = PoseScript(env)
        steps, accuracy = {}, []
        for protocol in ("paper", "released"):
            results = [
                type_sequences(oracle, env, sequences, seed=s, protocol=protocol) for s in range(args.seeds)
            ]
            steps[protocol] = [r.total_steps for r in results]
            accuracy += [r.accuracy for r in results]
        paper = ", ".join(f"{v[0]} ({algo})" for (platform, t, algo), v in PAPER_TABLE.items()
                          if platform == "sim" and t == task)  # fmt: skip
        cells = [f"{np.mean(v):.0f} ({min(v)}-{max(v)})" for v in steps.values()]
        if not env.unwrapped.task.continuous:  # the touch-only optimum, exact
            keys = env.unwrapped.task.keys
            reset, kept = touch_optimum(keys, sequences, "released"), touch_optimum(keys, sequences, "paper")
            cells = [f"{cells[0]}; touch only >= {kept:.0f}", f"{cells[1]}; touch only {reset:.0f}"]
        print(f"| {task} | {cells[0]} | {cells[1]} | {np.mean(accuracy):.3f} | {paper} |")


if __name__ == "__main__":
    main()
