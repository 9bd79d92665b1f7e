"""Where does a key-graph planner's typing go wrong, and where do its steps go?

Types the paper's sequences (the paper's protocol, seed 0, as ``tactile-braille evaluate``; with
``--typing-seeds`` other seeds too, so other start poses) with the last checkpoint of planner runs
and prints, run by run side by side: accuracy and steps, the steps a key took (typed right), how
often each kind of action was taken (moves and presses), and how each miss happened: a press where
the sensor stood, or the time limit.
With ``--reader`` it also reads the key under the sensor from random taps (at random cells of a
discrete task's grid; anywhere in a continuous task's workspace, at the planner's sensing depth),
and scores the reader against the key the grid says is there (on the keys and off them).
``--show N`` prints N missed keys' actions a run, and at each step the class read and the
state believed (``read>believed``). ``--refit --labels`` scores the refit's labels against the key
under each labelled frame (found from the stored sample the frame is). All three need what only a
measurement may know (the grid's keys, the pose), never given to the agent: a diagnostic, not a
result.

    python studies/planner_traces.py RUN_DIR [RUN_DIR ...] [--reader] [--show 5] [--set free_repeats=1]
    python studies/planner_traces.py RUN_DIR --refit --labels --set backtrack_prior=False

``--set NAME=VALUE`` types with a planner setting changed from the run's (one that acts at test time,
such as ``gamma``, ``free_repeats`` or ``repeat_penalty``; the learnt reader and graph are the
run's); with ``--refit`` the graph and the labels are refitted from the run's last replay first, so
that a graph setting (``backoff``, ``graph_prior``) acts too (the reader is the run's).
"""

from __future__ import annotations

import argparse
import ast
import dataclasses
import hashlib
from collections import Counter
from pathlib import Path

import numpy as np
import torch

import tactile_braille  # noqa: F401 - registers the environments
from tactile_braille.agents.planner import MOVES, PRESS, PlannerAgent, continuous_actions
from tactile_braille.agents.report import load_run
from tactile_braille.agents.run import CHECKPOINT_FILE
from tactile_braille.agents.training import make_replay
from tactile_braille.envs.registry import task_of
from tactile_braille.evaluation.protocol import paper_sequences, type_sequences

ACTION_NAMES = "UDLR"[:MOVES] + "P"
"""Each planner action's letter: the moves, then PRESS."""


def state_name(agent: PlannerAgent, state: int, names: list[str]) -> str:
    """A planning state's name: its class, then how it was reached: with ``entry_memory`` ``.`` (no
    move) or the move's letter; else, off the keys, the key and the move it left by (``-`` alone: the
    generic nothing)."""
    if agent.config.entry_memory:
        return names[agent.state_class[state]] + ".UDLR"[state % (MOVES + 1)]
    if state <= agent.keys:
        return names[agent.state_class[state]]
    key, move = divmod(state - agent.keys - 1, MOVES)
    return f"-{names[key]}{'UDLR'[move]}"


class Recorder:
    """The planner's test-time policy, with each action index it took, and what it read and believed
    at each step (class read, believed state), episode by episode."""

    def __init__(self, agent: PlannerAgent, names: list[str]) -> None:
        self.agent, self.names, self.episodes, self.steps = agent, names, [], []

    def policy_action(self, observation, step, explore, rng, deterministic=False):
        if not np.asarray(observation["previous_action"]).any():
            self.episodes.append([])
            self.steps.append([])
        action = self.agent.policy_action(observation, step, explore, rng, deterministic)
        read = self.agent.read(observation["observation"][None])[0].argmax()
        index = int(self.agent.action_indices(np.asarray(action)[None])[0])
        believed = int(self.agent._beliefs[explore].argmax())
        self.steps[-1].append(f"{self.names[read]}>{state_name(self.agent, believed, self.names)}")
        self.episodes[-1].append(index)
        return action


def traces(
    run_dir: str, settings: dict | None = None, refit: bool = False, seeds: tuple[int, ...] = (0,)
) -> dict:
    """Type the paper's sequences with the run's planner (its ``settings`` changed; with ``refit`` its
    graph refitted from the run's last replay with them, the reader kept), once for each typing seed in
    ``seeds`` (its sequences' start poses); what each key's episode did, over all of them (accuracy: the
    mean; steps: the mean total)."""
    config, env, agent = load_run(run_dir)
    if not isinstance(agent, PlannerAgent):
        raise SystemExit(f"{run_dir} is a {config.algo} run: this script reads planner runs")
    agent.config = dataclasses.replace(agent.config, **(settings or {}))
    agent._plan()  # the values again, for a planning setting (gamma, planning_sweeps)
    if agent.continuous is not None:  # its actions again, for a setting of them (move, sense_depth)
        agent.continuous = continuous_actions(agent.config.move, agent.config.sense_depth)
    if refit:
        buffer = make_replay(config, env)
        state = torch.load(Path(run_dir) / CHECKPOINT_FILE, weights_only=False, map_location="cpu")
        with np.load(Path(run_dir) / state["replay"]) as replay:
            if "remaining" not in replay.files:
                raise SystemExit(
                    f"{run_dir}'s replay has no episode boundaries (written before commit bb59807 "
                    "checkpointed them): it cannot be refitted as the run would"
                )
        buffer.load(Path(run_dir) / state["replay"])
        agent.refit(buffer)
    else:
        buffer = None
    keys = task_of(config.task).keys
    recorder = Recorder(agent, [*env.unwrapped.goal_keys, "-"])
    sequences = paper_sequences(keys)
    results = [type_sequences(recorder, env, sequences, seed=seed, protocol="paper") for seed in seeds]
    goals = [g for result in results for sequence in result.sequences for g in sequence]
    typed = [t for result in results for sequence in result.typed for t in sequence]
    steps = [s for result in results for sequence in result.steps for s in sequence]
    if len(recorder.episodes) != len(goals):
        raise RuntimeError(f"recorded {len(recorder.episodes)} episodes for {len(goals)} keys")
    misses = Counter()
    for goal, pressed, actions in zip(goals, typed, recorder.episodes, strict=True):
        if pressed != goal:
            misses["time limit" if actions[-1] < PRESS else "press"] += 1
    return {
        "run": run_dir, "name": Path(run_dir).name, "agent": agent, "env": env,
        "accuracy": float(np.mean([result.accuracy for result in results])),
        "steps": round(float(np.mean([result.total_steps for result in results]))), "misses": misses,
        "right_steps": Counter(s for s, g, t in zip(steps, goals, typed, strict=True) if g == t),
        "actions": Counter(ACTION_NAMES[a] for episode in recorder.episodes for a in episode),
        "episodes": list(zip(goals, typed, recorder.episodes, recorder.steps, strict=True)), "buffer": buffer,
    }  # fmt: skip


def task_classes(core, codes: np.ndarray, keys: int) -> np.ndarray:
    """The planner's class of layout key codes: the task's key, or ``keys`` (nothing) for -1 and a key
    not the task's."""
    classes = core._goal_of_code[codes]  # code -1 maps to -1
    return np.where(classes < 0, keys, classes)


def reader_accuracy(
    agent: PlannerAgent, env, taps: int = 2000, seed: int = 0
) -> tuple[float, float, float, Counter]:
    """The reader's accuracy on random taps (all, on the keys, off them) and its confusions ((truth,
    read) names: count): on a discrete task at random cells of the grid, on a continuous one anywhere
    in the workspace at its sensing depth, against the key a press there presses (the grid's label: a
    measurement's knowledge, not the agent's)."""
    core = env.unwrapped._core
    rng = np.random.default_rng(seed)
    if agent.continuous is None:
        rows, columns = core.grid_codes.shape
        r, c = rng.integers(rows, size=taps), rng.integers(columns, size=taps)
        codes = core.grid_codes[r, c]
        frames, _ = core.backend.discrete_taps(codes, np.zeros(taps, bool), core.cell_positions_mm[r, c], rng)
        pressed = codes
    else:
        xy = rng.uniform(core._workspace_low, core._workspace_high, (taps, 2)) + core._frame_origin
        sense = 5 + 3 * agent.config.sense_depth + core._depth_shift_mm
        frames, _ = core.backend.continuous_taps(xy[:, 0], xy[:, 1], np.full(taps, sense), rng)
        _, pressed = core.backend.continuous_taps(xy[:, 0], xy[:, 1], np.full(taps, 10.0), rng)
    truth = task_classes(core, pressed, agent.keys)
    read = agent.read(frames.reshape(taps, 100, 100, 1)).argmax(-1)
    right, on_keys = read == truth, truth < agent.keys
    names = [*env.unwrapped.goal_keys, "-"]
    confusions = Counter((names[t], names[r]) for t, r in zip(truth, read, strict=True) if t != r)
    return float(right.mean()), float(right[on_keys].mean()), float(right[~on_keys].mean()), confusions


def stored_samples(backend, frames: np.ndarray) -> np.ndarray:
    """The stored sample (its row of the dataset backend's observations) each of ``frames`` is, found
    by its bytes (a measurement's knowledge, never the agent's)."""
    index = {hashlib.sha1(frame.tobytes()).digest(): i for i, frame in enumerate(backend.observations)}
    return np.array([index[hashlib.sha1(frame.tobytes()).digest()] for frame in frames], np.int64)


def sample_codes(backend, continuous: bool) -> np.ndarray:
    """The layout code of the key under each stored sample (-1: none): a discrete dataset's key, or
    on a continuous grid what the deepest tap at the sample's place presses."""
    if not continuous:  # the dataset's samples of each key (code + 1: row 0 is NONE)
        code_of = np.full(len(backend.observations), -1)
        for slot, count in enumerate(backend._counts):
            code_of[backend._table[slot, :count]] = slot - 1
        return code_of
    flat = np.empty(len(backend._grid_rows), np.int64)
    flat[backend._grid_rows] = np.arange(len(flat))  # each sample's cell of the stored grid
    depths = backend._grid_shape[2]
    return backend._grid_pressed[backend._grid_rows[flat // depths * depths + depths - 1]]


def label_truth(row: dict) -> np.ndarray:
    """The class of each labelled frame of a refit (``--refit``): the key a press would press where it
    was taken (from the stored sample each frame is: a measurement's knowledge), the task's keys, then
    nothing."""
    agent, env = row["agent"], row["env"]
    core, buffer = env.unwrapped._core, row["buffer"]
    samples = stored_samples(core.backend, buffer.store.observations(agent.label_frames))
    codes = sample_codes(core.backend, agent.continuous is not None)[samples]
    return task_classes(core, codes, agent.keys)


def label_accuracy(row: dict) -> tuple[int, Counter]:
    """A refit's labels scored against :func:`label_truth`: labelled frames, confusions ((truth,
    label) names: count)."""
    truth, labels = label_truth(row), row["agent"].label_classes
    names = [*row["env"].unwrapped.goal_keys, "-"]
    return len(truth), Counter((names[t], names[c]) for t, c in zip(truth, labels, strict=True) if t != c)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("runs", nargs="+", help="planner run folders (each with its checkpoint.pt)")
    parser.add_argument("--reader", action="store_true", help="also score the reader on random taps")
    parser.add_argument("--show", type=int, default=0, help="print this many missed keys' actions a run")
    parser.add_argument(
        "--set",
        action="append",
        default=[],
        metavar="NAME=VALUE",
        help="type with this planner setting in place of the run's (Python literal)",
    )
    parser.add_argument(
        "--refit",
        action="store_true",
        help="refit the graph and labels from the run's last replay with --set's settings",
    )
    parser.add_argument(
        "--labels", action="store_true", help="with --refit: score its labels against the taps' keys"
    )
    parser.add_argument(
        "--typing-seeds", type=int, nargs="+", default=[0], metavar="SEED",
        help="type with each of these seeds (other sequence start poses; default 0, the evaluation's)",
    )  # fmt: skip
    args = parser.parse_args()
    if args.labels and not args.refit:
        parser.error("--labels scores a refit's labels: add --refit")
    settings = {}
    for setting in args.set:
        name, _, value = setting.partition("=")
        settings[name] = ast.literal_eval(value)
    rows = [traces(run, settings, args.refit, tuple(args.typing_seeds)) for run in args.runs]
    if len(args.typing_seeds) > 1:
        print(f"typing seeds {args.typing_seeds}: accuracy and steps are their means, misses their sums")
    width = max(len(row["name"]) for row in rows) + 2
    print(
        "run".ljust(width),
        "accuracy  steps  misses (press / time limit)  actions",
    )
    for row in rows:
        misses = row["misses"]
        actions = " ".join(f"{a}:{row['actions'][a]}" for a in ACTION_NAMES if row["actions"][a])
        print(row["name"].ljust(width), f"{row['accuracy']:.3f}  {row['steps']:5d}  "
              f"{misses['press']:3d} / {misses['time limit']:3d}{'':23s}{actions}")  # fmt: skip
    print("\nsteps a key typed right took: steps: keys")
    for row in rows:
        counts = row["right_steps"]
        print(row["name"].ljust(width), "  ".join(f"{s}: {counts[s]}" for s in sorted(counts)))  # fmt: skip
    if args.reader:
        print("\nreader accuracy on 2,000 random taps (all, on the keys, off them), its commonest confusions")
        for row in rows:
            every, on, off, confusions = reader_accuracy(row["agent"], row["env"])
            common = ", ".join(f"{t} read {r}: {n}" for (t, r), n in confusions.most_common(5))
            print(row["name"].ljust(width), f"{every:.3f}  {on:.3f}  {off:.3f}   {common}")
    if args.labels:
        print("\nthe refit's labels: labelled frames, wrong labels, then the commonest (truth labelled as)")
        for row in rows:
            labels, wrong = label_accuracy(row)
            common = ", ".join(f"{t} as {c}: {n}" for (t, c), n in wrong.most_common(5))
            print(row["name"].ljust(width), f"{labels:5d}  {sum(wrong.values()):4d}   {common}")
    for row in rows:
        missed = [episode for episode in row["episodes"] if episode[0] != episode[1]][: args.show]
        for goal, typed, actions, steps in missed:
            print(f"{row['run']}: {goal} typed as {typed}: {''.join(ACTION_NAMES[a] for a in actions)}")
            print("    " + " ".join(f"{s} {ACTION_NAMES[a]}" for s, a in zip(steps, actions, strict=True)))


if __name__ == "__main__":
    main()
