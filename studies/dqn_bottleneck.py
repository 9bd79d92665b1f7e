"""Where a discrete DQN run's test episodes fail: reading the key under the sensor, or reaching the goal.

For each checkpoint of a DQN run on a discrete task (the run's last, or copies
of its ``checkpoint.pt`` taken at several epochs) this measures two things:

- **perception**: the Q-network's PRESS column read as a key classifier. On
  the task keys' stored taps of a perturbed-taps dataset (``keys-train``, the
  images the environment serves, or ``keys-validation``, 50 held-out taps a
  key), ``argmax_g Q(image, g, PRESS)`` should be the key under the sensor,
  and under its own key as the goal the greedy action should be PRESS (the
  *hit* rate) while under any other goal it should not (the *false press*
  rate). The labels score the network here only; training never sees them.
  Beside it, the share of the last dense layer's ReLU units that are active
  (over the taps and goals): a Q-network whose units have died reads no image;
  how much the goal moves the PRESS value (its spread over the goals, for
  each tap): one that does not read the goal presses everywhere alike; and
  the norm of the encoder's features, beside which the goal one-hot joins.
- **control**: test episodes as the protocol runs them (random start and
  goal, greedy actions), split by how they end: the goal pressed, another
  key pressed, or the time limit reached without a press; and the steps of
  successful episodes against the shortest path on the grid from where each
  started (the environment's own cell, scoring only).

A run whose test return lags its perception is limited by control (how the
values spread over the grid); one whose wrong presses and perception errors
go together, by perception.

    python studies/dqn_bottleneck.py RUN [CHECKPOINT ...] [--episodes 100] [--dataset keys-train]
"""

from __future__ import annotations

import argparse
from collections import deque
from pathlib import Path

import numpy as np
import torch

import tactile_braille  # noqa: F401 - registers the environments
from tactile_braille.agents.report import load_run
from tactile_braille.agents.run import read_config
from tactile_braille.datasets.cache import default_dataset

PRESS = 4
"""The discrete tasks' PRESS action."""
MOVES = {0: (-1, 0), 1: (1, 0), 2: (0, -1), 3: (0, 1)}
"""UP, DOWN, LEFT, RIGHT as (row, column) steps on the key grid."""


@torch.no_grad()
def perception(agent, images: np.ndarray, keys: np.ndarray, goal_size: int) -> dict[str, float]:
    """The PRESS column as a classifier of ``images`` (N, 100, 100) whose key under the sensor is ``keys``
    (N,; goal indices), and the greedy action's hit and false-press rates."""
    reads, hits, false_presses, active, goal_spread, norms = [], [], [], [], [], []
    for chunk in np.array_split(np.arange(len(images)), max(1, len(images) // 256)):
        batch = torch.as_tensor(images[chunk][:, None])
        previous = torch.zeros(len(chunk), agent.num_actions)
        q = agent.q.every_goal(batch, previous).float()  # (N, goals, actions): one encoder pass
        hidden = agent.q.trunk.every_goal(batch, previous, goal_size)  # the last dense layer's ReLUs
        active.append(float((hidden > 0).float().mean()))
        goal_spread.append(float(q[:, :, PRESS].std(dim=1).mean()))  # how much the goal moves PRESS
        norms.append(float(agent.q.trunk.encode(batch).norm(dim=1).mean()))
        reads.append(q[:, :, PRESS].argmax(-1).numpy())
        greedy_presses = (q.argmax(-1) == PRESS).numpy()  # (N, G)
        own = np.zeros_like(greedy_presses)
        own[np.arange(len(chunk)), keys[chunk]] = True
        hits.append(greedy_presses[own])
        false_presses.append(greedy_presses[~own])
    return {
        "read": float(np.mean(np.concatenate(reads) == keys)),
        "hit": float(np.mean(np.concatenate(hits))),
        "false_press": float(np.mean(np.concatenate(false_presses))),
        "active": float(np.mean(active)),
        "goal_spread": float(np.mean(goal_spread)),
        "feature_norm": float(np.mean(norms)),
    }


def grid_distances(env) -> dict[tuple[int, int], dict[str, int]]:
    """Moves from each grid cell to each key's nearest cell (breadth-first, edges stop moves)."""
    grid = env.unwrapped.task.key_grid
    rows, columns = grid.shape
    distances: dict[tuple[int, int], dict[str, int]] = {}
    for start in ((r, c) for r in range(rows) for c in range(columns)):
        seen, queue, nearest = {start: 0}, deque([start]), {}
        while queue:
            cell = queue.popleft()
            nearest.setdefault(grid[cell[0]][cell[1]], seen[cell])
            for dr, dc in MOVES.values():
                step = (min(max(cell[0] + dr, 0), rows - 1), min(max(cell[1] + dc, 0), columns - 1))
                if step not in seen:
                    seen[step] = seen[cell] + 1
                    queue.append(step)
        distances[start] = nearest
    return distances


def control(agent, env, episodes: int, seed: int) -> dict[str, float]:
    """How the greedy test episodes end, and their steps against the shortest path (successes)."""
    distances = grid_distances(env)
    rng = np.random.default_rng(seed)
    ends = {"right": 0, "wrong": 0, "timeout": 0}
    excess = []
    for episode in range(episodes):
        observation, info = env.reset(seed=seed + episode)
        start, goal = tuple(int(i) for i in env.unwrapped._core.cell[0]), info["goal_key"]  # scoring only
        steps = 0
        while True:
            action = agent.policy_action(observation, 0, explore=False, rng=rng, deterministic=True)
            observation, reward, terminated, truncated, info = env.step(action)
            steps += 1
            if terminated or truncated:
                break
        if reward > 0:
            ends["right"] += 1
            excess.append(steps - (distances[start][goal] + 1))  # +1: the press
        else:
            ends["wrong" if terminated else "timeout"] += 1
    figures = {name: count / episodes for name, count in ends.items()}
    figures["excess_steps"] = float(np.mean(excess)) if excess else float("nan")
    return figures


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("run", type=Path, help="a DQN run on a discrete task")
    parser.add_argument(
        "checkpoints", nargs="*", type=Path, help="copies of its checkpoint.pt (default: its own)"
    )
    parser.add_argument("--episodes", type=int, default=100)
    parser.add_argument("--seed", type=int, default=5000, help="start seed of the test episodes")
    parser.add_argument("--dataset", default="keys-train", choices=("keys-train", "keys-validation"))
    args = parser.parse_args()
    config = read_config(args.run)
    if config.algo != "dqn" or "Discrete" not in config.task:
        raise SystemExit(f"{args.run}: a {config.algo} run of {config.task}; this reads a discrete DQN's Q")
    _, env, agent = load_run(args.run)
    torch.set_num_threads(1)
    goal_keys = list(env.unwrapped.goal_keys)
    data = default_dataset(args.dataset, progress=False)
    names = data.label_names()
    taps = np.flatnonzero(np.isin(names, goal_keys))
    images = data.observations[taps].reshape(len(taps), 100, 100)
    keys = np.array([goal_keys.index(name) for name in names[taps]])
    columns = [
        "epochs done", f"PRESS column reads the key ({args.dataset})", "presses its own key",
        "presses another", "active units", "PRESS spread over goals", "feature norm", "test: right",
        "wrong key", "time-out", "extra steps (right)",
    ]  # fmt: skip
    print("| " + " | ".join(columns) + " |")
    print("|" + "---|" * len(columns))
    for path in args.checkpoints or [args.run / "checkpoint.pt"]:
        state = torch.load(path, weights_only=False, map_location="cpu")
        agent.load_state_dict(state["agent"])
        seen = perception(agent, images, keys, len(goal_keys))
        ended = control(agent, env, args.episodes, args.seed)
        print(f"| {state['epoch']} | {seen['read']:.3f} | {seen['hit']:.3f} | {seen['false_press']:.3f} "
              f"| {seen['active']:.3f} | {seen['goal_spread']:.4f} | {seen['feature_norm']:.1f} "
              f"| {ended['right']:.2f} | {ended['wrong']:.2f} "
              f"| {ended['timeout']:.2f} | {ended['excess_steps']:.1f} |")  # fmt: skip


if __name__ == "__main__":
    main()
