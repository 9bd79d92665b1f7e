"""How well can a metric key map (the planner's ``locate``) be fitted from a run's own replay, and what
holds it back?

Refits a continuous planner run's last checkpoint and replay as ``locate`` would (its pairs of frames
of one episode, each frame's key, the commanded moves between them), fits a fresh map on them, and
prints side by side, for each way of fitting: the map's error in mm on 2,000 random taps (as
``planner_traces.py --locator``). The ways: ``commanded`` (what the agent has: the moves it commanded,
the keys its labels and reader name), ``true-moves`` (the moves the sensor really made: a move that
meets the workspace's edge stops there), ``true-keys`` (the key under each frame), and both. Before
that it prints how many pairs there are, how many of them a workspace edge cut short, and how many
pair keys are wrong. Every "true" quantity comes from the pose of the stored sample each frame is (a
measurement's knowledge, never the agent's): a diagnostic, not a result.

    python benchmarks/locator_fit.py RUN_DIR [--updates 3000] [--learning-rate 3e-3]
    python benchmarks/locator_fit.py RUN_DIR --ways commanded --type 0.1 0.3 0.5

``--type MARGIN ...`` then types the paper's sequences (the paper's protocol, seed 0) with each way's
map, its targets placed from the replay's presses, at each ``locate_margin``: what a run whose map
were fitted so would type (the reader and the graph are the run's).
"""

from __future__ import annotations

import argparse
import ast
import dataclasses
import time
from pathlib import Path

import numpy as np
import torch

import tactile_braille  # noqa: F401 - registers the environments
from planner_traces import locator_error, sample_codes, stored_samples
from tactile_braille.agents.locator import KeyLocator
from tactile_braille.agents.planner import PlannerAgent
from tactile_braille.agents.report import load_run
from tactile_braille.agents.run import CHECKPOINT_FILE
from tactile_braille.agents.training import make_replay
from tactile_braille.envs.registry import task_of
from tactile_braille.evaluation.protocol import paper_sequences, type_sequences
from tactile_braille.supervised.fit import adam

WAYS = ("commanded", "true-moves", "true-keys", "true-moves+true-keys")


def refitted(run_dir: str, settings: dict | None = None):
    """The run's planner with a (fresh) map and ``settings``, refitted from its last replay: (env, agent,
    buffer)."""
    config, env, agent = load_run(run_dir)
    if not isinstance(agent, PlannerAgent) or agent.continuous is None:
        raise SystemExit(f"{run_dir} is not a continuous planner run")
    agent.config = dataclasses.replace(agent.config, locate=True, **(settings or {}))
    agent.locator = KeyLocator(agent.keys, agent.config.hidden)
    buffer = make_replay(config, env)
    state = torch.load(Path(run_dir) / CHECKPOINT_FILE, weights_only=False, map_location="cpu")
    buffer.load(Path(run_dir) / state["replay"])
    agent.refit(buffer)
    return env, agent, buffer


def pair_truth(env, agent: PlannerAgent, buffer) -> tuple[np.ndarray, np.ndarray, float]:
    """The moves (pairs, 2) the sensor really made between each pair's frames (the actions' units,
    between the stored samples' poses), the key (pairs, 2) under each (-1: none of the task's), from
    each frame's stored sample, and the grid's spacing in the actions' units (a tap reads the nearest
    sample: a move's true length is known to within it)."""
    core = env.unwrapped._core
    backend = core.backend
    poses = np.asarray(backend.dataset.poses)
    samples = stored_samples(backend, buffer.store.observations(agent.pairs.ravel())).reshape(-1, 2)
    moves = (poses[samples[:, 1], :2] - poses[samples[:, 0], :2]) / core.task.max_move_mm
    keys = core._goal_of_code[sample_codes(backend, continuous=True)][samples]
    return moves.astype(np.float32), keys, float(backend._grid_step[:2].max() / core.task.max_move_mm)


def fit(env, agent: PlannerAgent, buffer, updates: int, learning_rate: float, seed: int = 0) -> tuple:
    """A fresh map fitted on the agent's pairs for ``updates`` steps of 64; its :func:`locator_error`."""
    torch.manual_seed(seed)
    agent.locator = KeyLocator(agent.keys, agent.config.hidden)
    agent.locator_optimiser = adam(agent.locator.parameters(), learning_rate, agent.config.adam_eps)
    rng = np.random.default_rng(seed)
    for _ in range(updates):
        batch = agent.sample(buffer, 64, rng)
        agent.fitted_size = buffer.size  # the pairs as refitted: no refit on the way
        agent.update(batch)
    return locator_error(agent, env)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("run", help="a continuous planner run folder (with its checkpoint.pt and replay)")
    parser.add_argument("--updates", type=int, default=3000, help="the map's steps, 64 pairs each")
    parser.add_argument("--learning-rate", type=float, default=3e-3)
    parser.add_argument("--ways", nargs="+", choices=WAYS, default=list(WAYS))
    parser.add_argument("--set", action="append", default=[], metavar="NAME=VALUE",
                        help="fit with this planner setting (e.g. locate_span, locate_accept)")  # fmt: skip
    parser.add_argument("--type", nargs="+", type=float, default=[], metavar="MARGIN",
                        help="type with each way's map at these locate_margin")  # fmt: skip
    args = parser.parse_args()
    torch.set_num_threads(1)
    settings = {name: ast.literal_eval(value) for name, _, value in (s.partition("=") for s in args.set)}
    env, agent, buffer = refitted(args.run, settings)
    moves, keys, spacing = pair_truth(env, agent, buffer)
    cut = np.abs(moves - agent.pair_moves).max(-1) > spacing + 1e-6  # more than the grid's rounding
    wrong = (keys != agent.pair_keys).mean(0)
    print(f"{len(moves)} pairs; {cut.mean():.0%} cut short by the workspace's edge; pair keys wrong: "
          f"first frames {wrong[0]:.0%}, second {wrong[1]:.0%}")  # fmt: skip
    commanded = agent.pairs, agent.pair_keys, agent.pair_moves
    print("way".ljust(22), "taps placed  error mm: median  90th pct  most   time")
    for way in args.ways:
        agent.pairs, agent.pair_keys, agent.pair_moves = commanded
        if "true-moves" in way:
            agent.pair_moves = moves
        if "true-keys" in way:
            keep = (keys >= 0).all(1)
            agent.pairs, agent.pair_keys, agent.pair_moves = (
                agent.pairs[keep],
                keys[keep],
                agent.pair_moves[keep],
            )
        started = time.perf_counter()
        placed, median, p90, most = fit(env, agent, buffer, args.updates, args.learning_rate)
        print(way.ljust(22), f"{placed:11d}  {median:14.2f}  {p90:8.2f}  {most:5.2f}  "
              f"{time.perf_counter() - started:4.0f}s")  # fmt: skip
        agent.end_epoch()  # the targets, from the replay's presses
        for margin in args.type:
            agent.config = dataclasses.replace(agent.config, locate_margin=margin)
            sequences = paper_sequences(task_of(env.spec.id).keys)
            typed = type_sequences(agent, env, sequences, seed=0, protocol="paper")
            print(f"    typing, locate_margin {margin}: {typed.accuracy:.3f} in {typed.total_steps} steps")


if __name__ == "__main__":
    main()
