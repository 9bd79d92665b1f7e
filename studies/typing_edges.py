"""How much does a continuous-task policy made in our world lean on its rules?

Our continuous environments stop the sensor at the workspace's edge (``edges="stop"``, as the real
rig's safety limits and the released robot environment do) and tap at the depth commanded. The
released simulator, in which the paper's Table III rows were trained, differs in both: the commanded
position runs on past the edge and only the tap is made at the nearest point inside
(``edges="overrun"``), so a move into the edge there is not a free way to find where the sensor is;
and each tap reads the stored sample 2 mm deeper than commanded (``tap_depth="released"``). This
script types the paper's sequences (the paper's protocol: no reset between keys, seed 0, as
``tactile-braille evaluate``) with the last checkpoint of runs made in our world, in our world, with
the overrunning edge alone, and in the released simulator's world (both rules), and prints side by
side: accuracy, steps, and the share of steps whose move the edge cut short or overran.

    python studies/typing_edges.py RUN_DIR [RUN_DIR ...]
"""

from __future__ import annotations

import argparse

import gymnasium as gym
import numpy as np

import tactile_braille  # noqa: F401 - registers the environments
from tactile_braille.agents.config import replace_settings
from tactile_braille.agents.report import load_run
from tactile_braille.agents.training import make_env
from tactile_braille.envs.core import WORLD_RULES
from tactile_braille.envs.registry import task_of
from tactile_braille.evaluation.protocol import paper_sequences, type_sequences

WORLDS = {
    "ours": {},
    "overrunning edge": {"edges": "overrun"},
    "released simulator": {"edges": "overrun", "tap_depth": "released"},
}
"""The worlds typed in, by the rules they change from ours."""
CUT_MM = 0.5
"""A move counts as cut short by the edge when the tap lands this far or more from where it was sent."""


class EdgeCount(gym.Wrapper):
    """Counts steps, and those whose move the workspace's edge cut short or overran (the tap landed
    :data:`CUT_MM` or more from where the move was sent)."""

    def __init__(self, env: gym.Env) -> None:
        super().__init__(env)
        self.steps = self.at_edge = 0

    def step(self, action):
        core = self.env.unwrapped._core
        sent = core.position_mm[0] + core.action_to_mm(np.clip(np.asarray(action), -1, 1)[None])[0, :2]
        result = super().step(action)
        tapped = core.sensor_pose_mm()[0, :2] - core._frame_origin
        self.steps += 1
        self.at_edge += bool(np.abs(tapped - sent).max() >= CUT_MM)
        return result


def measure(run_dir: str, sequences=None) -> list[tuple[str, float, int, float]]:
    """(world, accuracy, steps, share of steps at the edge) per world of :data:`WORLDS`, typing
    ``sequences`` (default: the paper's for the task)."""
    config, ours, agent = load_run(run_dir)
    if ours.unwrapped.world.keys() & set(WORLD_RULES):
        raise ValueError(f"{run_dir} was made in the released simulator's world; this script types "
                         "policies made in ours")  # fmt: skip
    if not task_of(config.task).continuous:
        raise ValueError(f"{run_dir} is a discrete task's run: its grid edges stop moves in every world")
    sequences = paper_sequences(task_of(config.task).keys) if sequences is None else sequences
    rows = []
    for world, rules in WORLDS.items():
        env = make_env(replace_settings(config, rules)) if rules else ours
        counted = EdgeCount(env)
        typed = type_sequences(agent, counted, sequences, seed=0, protocol="paper")
        rows.append((world, typed.accuracy, typed.total_steps, counted.at_edge / max(counted.steps, 1)))
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("runs", nargs="+", help="run folders of a continuous task (with checkpoint.pt)")
    args = parser.parse_args()
    print("| run | world | accuracy | steps | steps at the edge |")
    print("|---|---|---|---|---|")
    for run in args.runs:
        for world, accuracy, steps, share in measure(run):
            print(f"| {run} | {world} | {accuracy:.3f} | {steps} | {share:.0%} |")


if __name__ == "__main__":
    main()
