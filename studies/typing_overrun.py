"""Where does the paper's typing protocol start each key in the released simulator's world?

There (``edges="overrun"``) a move past the workspace's edge carries the commanded position on past
it and only the tap is made at the nearest point inside, and the paper's typing protocol does not
reset between keys: each key starts where the last press left the commanded position. A policy
that presses by pushing into the edge leaves it further out with each such press, and the next key
(on the far edge, say) starts that much further away, out of sight of a tap that lands at the edge
either way. This script types the paper's sequences (the paper's protocol, seed 0, as
``tactile-braille evaluate``) with the last checkpoint of each run, in the run's own world, and
prints how far past the workspace each key's attempt started (median and largest) and the accuracy
and steps a key of the keys started inside and of those started :data:`OUT_MM` or more outside;
``--by-key`` adds a row per goal key (which keys a run misses, and whether from outside).

    python studies/typing_overrun.py RUN_DIR [RUN_DIR ...] [--by-key]
"""

from __future__ import annotations

import argparse
from dataclasses import dataclass

import gymnasium as gym
import numpy as np

import tactile_braille  # noqa: F401 - registers the environments
from tactile_braille.agents.report import load_run
from tactile_braille.envs.registry import task_of
from tactile_braille.evaluation.protocol import paper_sequences, type_sequences

OUT_MM = 0.5
"""A key's attempt counts as started outside when its commanded position is this far or more out."""


class StartOverrun(gym.Wrapper):
    """Records, at each reset, how far (mm) the commanded position lies outside the workspace."""

    def __init__(self, env: gym.Env) -> None:
        super().__init__(env)
        self.starts_mm: list[float] = []

    def reset(self, **kwargs):
        result = super().reset(**kwargs)
        core = self.env.unwrapped._core
        commanded = core.position_mm[:1]
        self.starts_mm.append(float(np.linalg.norm(commanded - core._inside(commanded))))
        return result


@dataclass
class Overrun:
    """One run's keys, split by where their attempts started."""

    starts_mm: np.ndarray
    correct: np.ndarray
    steps: np.ndarray
    goals: np.ndarray

    def split(self, outside: bool, goal: str | None = None) -> tuple[int, float, float]:
        """(keys, accuracy, steps a key) of the keys started outside (or inside); of one goal key's only
        if ``goal``."""
        chosen = (self.starts_mm >= OUT_MM) == outside
        if goal is not None:
            chosen &= self.goals == goal
        if not chosen.any():
            return 0, float("nan"), float("nan")
        return int(chosen.sum()), float(self.correct[chosen].mean()), float(self.steps[chosen].mean())


def measure(run_dir: str, sequences=None) -> Overrun:
    """Types ``sequences`` (default: the paper's for the task) with the run's last checkpoint in its
    own world and returns each key's start overrun, whether it was typed right, and its steps."""
    config, env, agent = load_run(run_dir)
    if not task_of(config.task).continuous:
        raise ValueError(f"{run_dir} is a discrete task's run: its grid's edges stop every move")
    if config.edges != "overrun":
        raise ValueError(f"{run_dir} was made with edges={config.edges!r}: every key starts inside")
    sequences = paper_sequences(task_of(config.task).keys) if sequences is None else sequences
    counted = StartOverrun(env)
    typed = type_sequences(agent, counted, sequences, seed=0, protocol="paper")
    goals = [key for sequence in typed.sequences for key in sequence]
    pressed = [key for keys in typed.typed for key in keys]
    if len(counted.starts_mm) != len(goals):
        raise RuntimeError(f"{len(counted.starts_mm)} resets for {len(goals)} keys: one reset a key expected")
    return Overrun(
        starts_mm=np.array(counted.starts_mm),
        correct=np.array([g == p for g, p in zip(goals, pressed, strict=True)]),
        steps=np.array([s for steps in typed.steps for s in steps], dtype=float),
        goals=np.array(goals),
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("runs", nargs="+", help="run folders made with edges=overrun (with checkpoint.pt)")
    parser.add_argument("--by-key", action="store_true", help="a row per goal key too")
    args = parser.parse_args()
    print(f"| run | keys started {OUT_MM} mm or more out | median / largest start (mm) "
          "| inside: accuracy, steps a key | outside: accuracy, steps a key |")  # fmt: skip
    print("|---|---|---|---|---|")
    for run in args.runs:
        found = measure(run)
        inside, outside = found.split(False), found.split(True)
        print(f"| {run} | {outside[0]} of {len(found.starts_mm)} "
              f"| {np.median(found.starts_mm):.1f} / {found.starts_mm.max():.1f} "
              f"| {inside[1]:.3f}, {inside[2]:.1f} | {outside[1]:.3f}, {outside[2]:.1f} |")  # fmt: skip
        for goal in dict.fromkeys(found.goals) if args.by_key else ():
            inside, outside = found.split(False, goal), found.split(True, goal)
            print(f"| {run}, goal {goal} | {outside[0]} of {inside[0] + outside[0]} | "
                  f"| {inside[1]:.3f}, {inside[2]:.1f} | {outside[1]:.3f}, {outside[2]:.1f} |")  # fmt: skip


if __name__ == "__main__":
    main()
