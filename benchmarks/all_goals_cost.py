"""What an all-goals update costs: one update of each agent with and without ``all_goals``, side by side.

The `paper` preset's agents (bf16, batch 32, one thread) on a replay of real
environment steps; the two variants are timed in alternating rounds, so that
a shared, noisy machine slows both alike, and the ratio is the figure to read.
The alphabet's 27 goals run the dense layers 27 times per transition; the
arrows' 4, four times; the encoder runs once either way.

    python benchmarks/all_goals_cost.py [--updates 10] [--rounds 5]
"""

from __future__ import annotations

import argparse
import dataclasses
import statistics
import time

import numpy as np
import torch

import tactile_braille  # noqa: F401 - registers the environments
from tactile_braille.agents import preset_config
from tactile_braille.agents.replay import GoalOutcomes
from tactile_braille.agents.training import make_agent, make_env
from train_throughput import random_replay  # this folder's

CASES = (
    ("dqn", "tactile_braille/DiscreteArrows-v0"),
    ("dqn", "tactile_braille/DiscreteAlphabet-v0"),
    ("sac_discrete", "tactile_braille/DiscreteArrows-v0"),
    ("sac", "tactile_braille/ContinuousArrows-v0"),
    ("sac", "tactile_braille/ContinuousAlphabet-v0"),
)


def update_ms(agent, batches: list[dict]) -> float:
    start = time.perf_counter()
    for batch in batches:
        agent.update(batch)
    return (time.perf_counter() - start) / len(batches) * 1e3


def timing_arguments(doc: str, updates: int, rounds: int) -> argparse.Namespace:
    """The command line of a script that times variants of an update side by side (one torch thread)."""
    parser = argparse.ArgumentParser(description=doc.splitlines()[0])
    parser.add_argument("--updates", type=int, default=updates, help="updates per timing")
    parser.add_argument("--rounds", type=int, default=rounds, help="alternating timings of each variant")
    args = parser.parse_args()
    torch.set_num_threads(1)
    return args


def alternating_ms(agents: dict, batches: list[dict], rounds: int, warm_up: int = 2) -> dict:
    """Median milliseconds an update of each agent takes, the agents timed in turn ``rounds`` times (a
    shared, noisy machine slows each alike), after ``warm_up`` updates each."""
    for agent in agents.values():
        update_ms(agent, batches[:warm_up])
    times: dict = {key: [] for key in agents}
    for _ in range(rounds):
        for key, agent in agents.items():
            times[key].append(update_ms(agent, batches))
    return {key: statistics.median(values) for key, values in times.items()}


def main() -> None:
    args = timing_arguments(__doc__, updates=10, rounds=5)
    print(f"{'agent':<14}{'task':<22}{'single goal':>13}{'all goals':>11}{'ratio':>7}")
    for algo, task in CASES:
        config = preset_config("paper", task, algo, precision="bf16")
        env = make_env(config)
        buffer, rng = random_replay(env, extras=(GoalOutcomes(),)), np.random.default_rng(0)  # serves both
        batches = [buffer.sample(config.agent.batch_size, rng) for _ in range(args.updates)]
        variants = {every: dataclasses.replace(config.agent, all_goals=every) for every in (False, True)}
        agents = {
            every: make_agent(dataclasses.replace(config, agent=agent), env)
            for every, agent in variants.items()
        }
        medians = alternating_ms(agents, batches, args.rounds)
        single, every = medians[False], medians[True]
        print(f"{algo:<14}{task.split('/')[1]:<22}{single:>10.1f} ms{every:>8.1f} ms{every / single:>7.2f}")
        env.close()


if __name__ == "__main__":
    main()
