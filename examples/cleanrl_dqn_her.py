"""DQN with hindsight relabelling in one file, CleanRL style, on a discrete braille task; then scored.

Everything the agent does is on this page: the network, the replay, the
relabelling, the loop. It learns from the observation dictionary and the
reward only (the ``tactile`` track), and is scored by
``tactile_braille.evaluation.evaluate_policy`` like every other agent.

    python examples/cleanrl_dqn_her.py --task DiscreteArrows-v0 --steps 6000 --seed 0 \\
        --output results/leaderboard/cleanrl/DiscreteArrows-v0__dqn_her__0.json

Relabelling: any key press ends an episode and only that press achieves a
goal, so the one informative hindsight goal is the key the episode ended on
("final" and "future" strategies coincide). ``--her sampled`` (default): a
sampled transition takes it as its goal with probability ``--her-fraction``,
its reward recomputed by the environment's ``compute_reward``. ``--her
paper``: the paper's rule, an episode that ended on a wrong key is stored a
second time with that key as its goal (no relabelling when sampling).
"""

from __future__ import annotations

import argparse
import random
import time
from pathlib import Path

import gymnasium as gym
import numpy as np
import torch
from torch import nn

import tactile_braille  # noqa: F401 - registers the environments
from tactile_braille.evaluation.results import make_result, write_result
from tactile_braille.evaluation.scoring import evaluate_policy

METHODS = {"sampled": "CleanRL-style DQN + HER", "paper": "CleanRL-style DQN + the paper's HER"}


def parse_args(argv=None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--task", default="DiscreteArrows-v0", help="a discrete task")
    parser.add_argument("--steps", type=int, default=6_000, help="environment steps to train")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--output", type=Path, required=True, help="the results file to write")
    parser.add_argument("--dataset", type=Path, help="the dataset backend's file (default: the cached one)")
    parser.add_argument("--learning-rate", type=float, default=1e-4)
    parser.add_argument("--gamma", type=float, default=0.95)
    parser.add_argument("--batch-size", type=int, default=32)
    parser.add_argument("--learning-starts", type=int, default=500)
    parser.add_argument("--target-every", type=int, default=500, help="steps between target network copies")
    parser.add_argument(
        "--exploration-fraction", type=float, default=0.3, help="of the run, epsilon 1 -> 0.05"
    )
    parser.add_argument("--her", choices=("sampled", "paper"), default="sampled", help="the relabelling rule")
    parser.add_argument("--her-fraction", type=float, default=0.8, help="--her sampled: relabelled share")
    parser.add_argument("--threads", type=int, default=1)
    return parser.parse_args(argv)


class QNetwork(nn.Module):
    """A small CNN on the tactile image, joined by the previous action and the desired goal."""

    def __init__(self, env: gym.Env) -> None:
        super().__init__()
        spaces = env.observation_space
        self.image = nn.Sequential(
            nn.Conv2d(1, 32, 8, stride=4), nn.ReLU(), nn.Conv2d(32, 64, 4, stride=2), nn.ReLU(),
            nn.Conv2d(64, 64, 3, stride=1), nn.ReLU(), nn.Flatten(),
        )  # fmt: skip
        with torch.no_grad():
            features = self.image(torch.zeros(1, 1, *spaces["observation"].shape[:2])).shape[1]
        extra = spaces["previous_action"].shape[0] + spaces["desired_goal"].shape[0]
        self.head = nn.Sequential(
            nn.Linear(features + extra, 256), nn.ReLU(), nn.Linear(256, env.action_space.n)
        )

    def forward(self, image, previous_action, goal):
        x = self.image(image.permute(0, 3, 1, 2).float() / 255.0)
        return self.head(torch.cat([x, previous_action, goal], dim=1))


class EpisodeReplay:
    """Transitions, and the episode each belongs to, so that a goal can be relabelled in hindsight."""

    def __init__(self, env: gym.Env, capacity: int) -> None:
        spaces = env.observation_space
        self.image = np.zeros((capacity + 1, *spaces["observation"].shape), np.uint8)  # s_t (and s_t+1)
        self.next_image = np.zeros_like(self.image)
        self.previous = np.zeros((capacity + 1, spaces["previous_action"].shape[0]), np.float32)
        self.next_previous = np.zeros_like(self.previous)
        self.goal = np.zeros((capacity + 1, spaces["desired_goal"].shape[0]), np.float32)
        self.achieved = np.zeros_like(self.goal)  # the goal the step achieved
        self.action = np.zeros(capacity + 1, np.int64)
        self.terminated = np.zeros(capacity + 1, np.float32)
        self.final = np.zeros_like(self.goal)  # the goal the transition's episode ended on
        self.size, self.episode_start, self.complete = 0, 0, 0

    def add(self, observation, action, next_observation, terminated: bool) -> None:
        i = self.size
        self.image[i], self.previous[i] = observation["observation"], observation["previous_action"]
        self.next_image[i], self.next_previous[i] = (
            next_observation["observation"],
            next_observation["previous_action"],
        )
        self.goal[i], self.achieved[i] = observation["desired_goal"], next_observation["achieved_goal"]
        self.action[i], self.terminated[i] = action, terminated
        self.size += 1

    def end_episode(self, copy_wrong_press: bool = False) -> None:
        """Close the episode; with ``copy_wrong_press`` (the paper's HER), an episode that ended on a key
        other than its goal is stored again with that key as its goal."""
        start, end = self.episode_start, self.size
        self.final[start:end] = self.achieved[end - 1]
        pressed, wanted = self.achieved[end - 1], self.goal[end - 1]
        if copy_wrong_press and pressed.any() and not np.array_equal(pressed, wanted):
            copy = slice(end, 2 * end - start)
            for array in (self.image, self.next_image, self.previous, self.next_previous, self.achieved,
                          self.action, self.terminated, self.final):  # fmt: skip
                array[copy] = array[start:end]
            self.goal[copy] = pressed
            self.size = 2 * end - start
        self.episode_start = self.complete = self.size

    def sample(self, env: gym.Env, batch: int, her_fraction: float, rng: np.random.Generator) -> dict:
        index = rng.integers(self.complete, size=batch)
        goal = self.goal[index].copy()
        relabel = (rng.random(batch) < her_fraction) & (self.final[index].sum(axis=1) > 0)
        goal[relabel] = self.final[index[relabel]]
        reward = env.unwrapped.compute_reward(self.achieved[index], goal, None)
        tensors = {"image": self.image[index], "previous": self.previous[index], "goal": goal,
                   "next_image": self.next_image[index], "next_previous": self.next_previous[index],
                   "action": self.action[index], "reward": reward.astype(np.float32),
                   "terminated": self.terminated[index]}  # fmt: skip
        return {name: torch.as_tensor(value) for name, value in tensors.items()}


def train(args: argparse.Namespace) -> tuple[QNetwork, float]:
    random.seed(args.seed)
    torch.manual_seed(args.seed)
    torch.set_num_threads(args.threads)
    rng = np.random.default_rng(args.seed)
    env = gym.make(f"tactile_braille/{args.task}", **({"dataset": args.dataset} if args.dataset else {}))
    if not isinstance(env.action_space, gym.spaces.Discrete):
        raise SystemExit(f"{args.task} is continuous; this DQN needs a discrete task")
    q, target = QNetwork(env), QNetwork(env)
    target.load_state_dict(q.state_dict())
    optimizer = torch.optim.Adam(q.parameters(), lr=args.learning_rate)
    replay = EpisodeReplay(env, 2 * args.steps if args.her == "paper" else args.steps)
    her_fraction = args.her_fraction if args.her == "sampled" else 0.0

    start = time.perf_counter()
    observation, _ = env.reset(seed=args.seed)
    for step in range(args.steps):
        epsilon = max(0.05, 1.0 - step / max(args.exploration_fraction * args.steps, 1) * 0.95)
        explore = rng.random() < epsilon
        action = int(rng.integers(env.action_space.n)) if explore else act(q, observation)
        next_observation, _, terminated, truncated, _ = env.step(action)
        replay.add(observation, action, next_observation, terminated)
        observation = next_observation
        if terminated or truncated:
            replay.end_episode(copy_wrong_press=args.her == "paper")
            observation, _ = env.reset()

        if step >= args.learning_starts and replay.complete > 0:
            data = replay.sample(env, args.batch_size, her_fraction, rng)
            with torch.no_grad():
                next_q = target(data["next_image"], data["next_previous"], data["goal"]).max(dim=1).values
                td_target = data["reward"] + args.gamma * next_q * (1.0 - data["terminated"])
            value = q(data["image"], data["previous"], data["goal"]).gather(1, data["action"][:, None])[:, 0]
            loss = nn.functional.mse_loss(value, td_target)
            optimizer.zero_grad()
            loss.backward()
            optimizer.step()
        if step % args.target_every == 0:
            target.load_state_dict(q.state_dict())
    return q, time.perf_counter() - start


@torch.no_grad()
def act(q: QNetwork, observation: dict) -> int:
    """The greedy action for one observation dictionary: this is the policy the benchmark scores."""
    batch = {k: torch.as_tensor(v)[None] for k, v in observation.items()}
    return int(q(batch["observation"], batch["previous_action"], batch["desired_goal"]).argmax())


def main(argv=None) -> int:
    args = parse_args(argv)
    if args.output.exists():
        raise SystemExit(f"{args.output} exists; choose another name")
    q, seconds = train(args)
    report = evaluate_policy(lambda observation: act(q, observation), args.task, dataset=args.dataset)
    result = make_result(
        report, method=METHODS[args.her], seed=args.seed, env_steps=args.steps,
        notes=f"examples/cleanrl_dqn_her.py; {seconds / 60:.1f} min on {args.threads} CPU thread(s)",
    )  # fmt: skip
    write_result(result, args.output)
    print(f"{args.task} seed {args.seed}: accuracy {report.accuracy:.3f}, {report.total_steps} steps "
          f"({args.steps} env steps in {seconds / 60:.1f} min); wrote {args.output}")  # fmt: skip
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
