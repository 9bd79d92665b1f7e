"""Whether a discrete SAC run's policy follows its critics, on the states its policy visits.

Loads each run's last checkpoint, runs its deterministic policy (the most probable action, as
the test episodes) from fresh starts and goals, and at every step compares the policy's action
with the critics' best one (the minimum of the two critics, as the actor's loss uses):

- agreement: the share of steps where the policy's action is the critics' best;
- regret: how much less the critics value the policy's action than their best;
- top-2 gap: how far apart the critics' two best actions are (small gaps make disagreement cheap);
- presses: the share of steps the policy presses, and the critics would.

A converged run agrees at nearly every step. A policy far more confident than its agreement
has committed to actions its critics no longer prefer: with a temperature near zero the
softmax's gradient towards an improbable action is scaled by its probability.

    python studies/policy_critic_agreement.py runs/table3/paper/DiscreteAlphabet-v0__sac_discrete__0
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
import torch

from tactile_braille.agents.networks import observation_tensors
from tactile_braille.agents.report import load_run
from tactile_braille.agents.run import read_config, read_progress


def load_agent(run: Path):
    """The run's environment, its agent at the last checkpoint, and that checkpoint's epoch (from 0)."""
    if (algo := read_config(run).algo) != "sac_discrete":
        raise ValueError(f"{run}: a {algo} run; this compares a discrete SAC's policy and critics")
    _, env, agent = load_run(run)
    return env, agent, len(read_progress(run)) - 1


@torch.no_grad()
def step_measures(env, agent, episodes: int, seed: int) -> np.ndarray:
    """Per visited step: (agrees, regret, top-2 gap, the policy presses, the critics would, max prob)."""
    press = agent.num_actions - 1  # PRESS is the last discrete action
    rows = []
    for episode in range(episodes):
        observation, _ = env.reset(seed=seed + episode)
        done = False
        while not done:
            inputs = observation_tensors(observation, agent.device)
            probabilities = agent.actor(*inputs)[0][0].numpy()
            q = torch.min(agent.critics[0](*inputs), agent.critics[1](*inputs))[0].float().numpy()
            action, best = int(probabilities.argmax()), int(q.argmax())
            top = np.sort(q)
            rows.append((action == best, q[best] - q[action], top[-1] - top[-2], action == press,
                         best == press, probabilities.max()))  # fmt: skip
            observation, _, terminated, truncated, _ = env.step(action)
            done = terminated or truncated
    return np.asarray(rows, dtype=float)


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("runs", nargs="+", type=Path)
    parser.add_argument("--episodes", type=int, default=30)
    parser.add_argument("--seed", type=int, default=3000, help="start seed of the episodes")
    args = parser.parse_args()
    torch.set_num_threads(1)
    columns = ["run", "epoch", "steps", "agreement", "regret (mean, median)", "top-2 gap", "max prob",
               "presses: policy, critics"]  # fmt: skip
    print("| " + " | ".join(columns) + " |")
    print("|---|---|---|---|---|---|---|---|")
    for run in args.runs:
        env, agent, epoch = load_agent(run)
        rows = step_measures(env, agent, args.episodes, args.seed)
        agree, regret, gap, presses, best_presses, confidence = rows.T
        print(
            f"| {run.name} | {epoch + 1} | {len(rows)} | {agree.mean():.2f} | {regret.mean():.3f}, "
            f"{np.median(regret):.3f} | {gap.mean():.3f} | {confidence.mean():.2f} | "
            f"{presses.mean():.2f}, {best_presses.mean():.2f} |"
        )


if __name__ == "__main__":
    main()
