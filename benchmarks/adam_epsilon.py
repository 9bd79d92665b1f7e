"""How much of each Adam step Adam's epsilon leaves the `paper` DQN, layer by layer, with our initial
weights and with the released code's.

Adam moves a weight by about ``lr * m / (sqrt(v) + eps)``: where the gradient's root mean square
``sqrt(v)`` is small beside ``eps``, the step shrinks by ``sqrt(v) / (sqrt(v) + eps)``. The `paper`
preset takes the released code's epsilon, 1e-4 (TensorFlow's, the same as torch's once Adam's bias
correction has faded, after a few thousand updates); torch's default is 1e-8. This script trains the
`paper` DQN for ``--updates`` updates on a replay of random steps of the discrete alphabet (epsilon
1e-8, so that the gradients, not the epsilon, set the moments), once with each initialisation, and
prints per group of weights the median ``sqrt(v)`` and the mean share of its step a weight keeps at
epsilon 1e-4, side by side. Given run folders (``RUN``), it prints the same from each run's last
checkpoint: the moments of a real run.

    python benchmarks/adam_epsilon.py [--updates 300] [RUN ...]
"""

from __future__ import annotations

import argparse

import numpy as np
import torch

import tactile_braille  # noqa: F401 - registers the environments
from tactile_braille.agents import preset_config
from tactile_braille.agents.training import make_agent, make_env
from tactile_braille.supervised.networks import conv_output_size
from train_throughput import random_replay  # this folder's

TASK = "tactile_braille/DiscreteAlphabet-v0"
EPSILON = 1e-4
"""The released code's Adam epsilon, the `paper` preset's."""


def groups(names: list[str], goal_size: int, previous_size: int) -> dict[str, tuple[str, slice | None]]:
    """The DQN's weights in groups: (parameter name, the dense layer's input columns or None)."""
    features = conv_output_size()
    found = {
        "conv 1": ("trunk.encoder.layers.0.weight", None),
        "conv 2": ("trunk.encoder.layers.2.weight", None),
        "conv 3": ("trunk.encoder.layers.4.weight", None),
        "dense, from the image": ("trunk.dense.0.weight", slice(0, features)),
        "dense, from the goal": ("trunk.dense.0.weight", slice(features, features + goal_size)),
        "dense, from the last action": ("trunk.dense.0.weight", slice(features + goal_size, None)),
        "value head": ("value.weight", None),
        "advantage head": ("advantage.weight", None),
    }
    return {label: (name, columns) for label, (name, columns) in found.items() if name in names}


def root_moments(names: list[str], optimiser_state: dict, goal_size: int, previous_size: int) -> dict:
    """Per group, the bias-corrected sqrt(v) of each weight (a flat array), from an Adam state dict."""
    group = optimiser_state["param_groups"][0]
    beta2 = group["betas"][1]
    moments = {}
    for name, index in zip(names, group["params"], strict=True):
        state = optimiser_state["state"].get(index)
        if state is None:
            continue
        step = float(state["step"])
        moments[name] = (state["exp_avg_sq"].float() / (1 - beta2**step)).sqrt().numpy()
    found = {}
    for label, (name, columns) in groups(list(moments), goal_size, previous_size).items():
        values = moments[name] if columns is None else moments[name][:, columns]
        found[label] = values.ravel()
    return found


def summary(values: np.ndarray) -> str:
    kept = np.mean(values / (values + EPSILON))
    return f"{np.median(values):9.1e} {kept:6.2f}"


def print_table(columns: dict[str, dict[str, np.ndarray]]) -> None:
    titles = list(columns)
    print(f"{'':<30}" + "".join(f"{title:>17}" for title in titles))
    print(f"{'weights':<30}" + "".join(f"{'sqrt(v)':>10} {'kept':>6}" for _ in titles))
    for label in next(iter(columns.values())):
        print(f"{label:<30}" + "".join(f"{summary(columns[t][label]):>17}" for t in titles))


def fresh(updates: int) -> dict[str, dict[str, np.ndarray]]:
    """Moments after ``updates`` updates of a fresh `paper` DQN, per initialisation."""
    config = preset_config("paper", TASK, "dqn", threads=1)
    env = make_env(config)
    buffer = random_replay(env, steps=2_000)
    goal_size = env.observation_space["desired_goal"].shape[0]
    previous_size = env.observation_space["previous_action"].shape[0]
    columns = {}
    for weights in ("he", "released"):
        torch.manual_seed(0)
        rng = np.random.default_rng(0)
        agent = make_agent(
            preset_config("paper", TASK, "dqn", agent={"weights_init": weights, "adam_eps": 1e-8}), env
        )
        for _ in range(updates):
            agent.update(buffer.sample(32, rng))
        names = [name for name, _ in agent.q.named_parameters()]
        columns[f"init {weights}"] = root_moments(
            names, agent.optimiser.state_dict(), goal_size, previous_size
        )
    env.close()
    return columns


def from_runs(runs: list[str]) -> dict[str, dict[str, np.ndarray]]:
    """Moments in each run's last checkpoint."""
    columns = {}
    for run in runs:
        checkpoint = torch.load(f"{run}/checkpoint.pt", map_location="cpu", weights_only=False)
        weights = checkpoint["agent"]["q"]
        goal_size = weights["trunk.dense.0.weight"].shape[1] - conv_output_size() - 5
        title = f"{run.rstrip('/').split('/')[-1][-11:]} e{checkpoint['epoch']}"
        columns[title] = root_moments(list(weights), checkpoint["agent"]["optimiser"], goal_size, 5)
    return columns


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("runs", nargs="*", metavar="RUN", help="run folders of the DQN (their checkpoint.pt)")
    parser.add_argument("--updates", type=int, default=300)
    args = parser.parse_args()
    torch.set_num_threads(1)
    print(f"median sqrt(v) per group, and 'kept': the mean share of its Adam step a weight keeps at "
          f"epsilon {EPSILON:g} (1.00 at torch's 1e-8)\n")  # fmt: skip
    print(f"`paper` DQN on {TASK.split('/')[1]}, {args.updates} updates on 2,000 random steps:")
    print_table(fresh(args.updates))
    if args.runs:
        print("\nthe runs' last checkpoints:")
        print_table(from_runs(args.runs))


if __name__ == "__main__":
    main()
