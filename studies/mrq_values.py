"""What a discrete MR.Q run's value and policy say on the task's start observations.

Loads each run's last checkpoint and, on ``--starts`` fresh start observations, reads with the
agent's own networks:

- the value of each action (the clipped double Q, in the value's reward-scaled units) under every
  goal of the task, the observation otherwise unchanged: *goal spread* is how far apart the goals
  put an action's value, the most over the actions (0: the value does not read the goal);
- the policy's greedy action (its largest pre-activation) beside the value's best action;
- the value of the policy's relaxed action (the softmax of its pre-activations at the Gumbel
  temperature) beside the best one-hot action's, the only actions the value is trained on: a
  relaxed action valued above every one-hot action is the value's extrapolation, which the
  policy's loss climbs.

    python studies/mrq_values.py runs/DA_mrq_b64_preact0.01_100 [--starts 20]
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
import torch
from torch.nn import functional as F

from tactile_braille.agents.networks import observation_tensors
from tactile_braille.agents.report import load_run


def load_agent(run: Path):
    """The run's environment and its agent at the last checkpoint (a discrete MR.Q run only)."""
    config, env, agent = load_run(run)
    if config.algo != "mrq" or not agent.discrete:
        raise ValueError(f"{run}: not a discrete MR.Q run; this reads a discrete MR.Q's value and policy")
    return env, agent


@torch.no_grad()
def start_measures(env, agent, starts: int, seed: int) -> list[dict]:
    """Per start observation: ``values`` (goals x actions), the policy's greedy action, the value's
    best action under the asked goal, and the values of the relaxed and of the best one-hot action."""
    actions = torch.eye(agent.action_size)
    rows = []
    for start in range(starts):
        observation, _ = env.reset(seed=seed + start)
        goals = np.eye(len(observation["desired_goal"]), dtype=np.float32)
        values = []
        for goal in goals:
            zs = agent.encoder.zs(*observation_tensors({**observation, "desired_goal": goal}, agent.device))
            zs = zs.float().expand(agent.action_size, -1)
            values.append(agent.value(agent.encoder.zsa(zs, actions)).float().min(-1).values.numpy())
        values = np.asarray(values)
        asked = int(observation["desired_goal"].argmax())
        zs = agent.encoder.zs(*observation_tensors(observation, agent.device)).float()
        pre = agent.policy.layers(zs).float()
        relaxed = F.softmax(pre / agent.config.gumbel_tau, -1)
        rows.append({
            "values": values, "goal": asked, "greedy": int(pre.argmax()), "best": int(values[asked].argmax()),
            "relaxed": float(agent.value(agent.encoder.zsa(zs, relaxed)).float().min(-1).values),
            "one_hot": float(values[asked].max()),
        })  # fmt: skip
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("runs", nargs="+", type=Path)
    parser.add_argument("--starts", type=int, default=20, help="start observations read (default 20)")
    parser.add_argument("--seed", type=int, default=1000, help="the first start's seed (default 1000)")
    args = parser.parse_args()
    for run in args.runs:
        env, agent = load_agent(run)
        rows = start_measures(env, agent, args.starts, args.seed)
        spread = [float(np.ptp(row["values"], axis=0).max()) for row in rows]
        print(f"{run}: {len(rows)} starts")
        print(f"  goal spread of the values: median {np.median(spread):.3f}, largest {max(spread):.3f}")
        agree = sum(r["greedy"] == r["best"] for r in rows)
        above = sum(r["relaxed"] > r["one_hot"] for r in rows)
        print(f"  the policy's greedy action is the value's best: {agree}")
        print(f"  the relaxed action valued above every one-hot action: {above}")
        for row in rows:
            print(f"  goal {row['goal']}: values {np.round(row['values'][row['goal']], 2)}, policy "
                  f"{row['greedy']}, value's best {row['best']}, relaxed {row['relaxed']:.2f} "
                  f"against {row['one_hot']:.2f}")  # fmt: skip


if __name__ == "__main__":
    main()
