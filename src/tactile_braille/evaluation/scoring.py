"""Score any agent on the paper's typing protocol: :func:`evaluate_policy` and its :class:`TypingReport`.

A policy is any callable from the environment's observation dictionary to an
action: a plain function, a Stable-Baselines3 model's ``predict`` wrapped in
one line, a torch module. Our own agents go through the same function.

>>> import numpy as np
>>> report = evaluate_policy(lambda observation: 4, "DiscreteArrows-v0")  # always PRESS
>>> 0.0 <= report.accuracy <= 1.0, len(report.fingerprint)
(True, 64)

The **protocol fingerprint** hashes everything that decides the score: the
task, the protocol, the key sequences, the episode limit, the start-pose
seed, the world the observations come from (backend, dataset procedure and
generator version, keyboard and sensor parameters; not where the dataset
file lies) and the project's version. Two reports are comparable exactly
when their fingerprints match.
"""

from __future__ import annotations

import functools
import hashlib
import itertools
import json
import warnings
from collections.abc import Callable
from dataclasses import MISSING, asdict, dataclass, field, fields

import gymnasium as gym
import numpy as np

from tactile_braille._tasks import KEY_SETS
from tactile_braille._version import __version__
from tactile_braille.agents.config import TRACKS
from tactile_braille.envs.core import _MOVES, _PRESS, PROPRIO_KEY
from tactile_braille.envs.registry import task_name, task_of
from tactile_braille.envs.tasks import Task
from tactile_braille.evaluation.protocol import (
    PROTOCOLS,
    SENTENCES,
    paper_sequences,
    text_keys,
    type_sequences,
)

FINGERPRINT_FORMAT = 1
"""Raised whenever what the fingerprint covers changes, so that old and new ones never match."""


class PolicyError(ValueError):
    """A policy returned an action the task's action space does not hold."""


# ------------------------------------------------------------------ policies
class CheckedPolicy:
    """A callable ``observation -> action`` behind the agents' ``policy_action`` interface, its actions
    checked against the action space (shape, dtype, range, finite) before the environment sees them."""

    def __init__(self, policy: Callable, action_space: gym.Space, task: str) -> None:
        if not callable(policy):
            raise TypeError(f"a policy must be callable (observation -> action), got {type(policy).__name__}")
        self.policy, self.action_space, self.task = policy, action_space, task

    def policy_action(self, observation, step, explore, rng, deterministic=False):
        return self.check(self.policy(observation))

    def check(self, action):
        """The action as the environment takes it, or a :class:`PolicyError` saying what is wrong."""
        space = self.action_space
        try:
            value = np.asarray(action.detach().cpu() if hasattr(action, "detach") else action)
        except (TypeError, ValueError) as error:
            raise PolicyError(
                f"the policy returned {action!r} for {self.task}: not an array ({error})"
            ) from None
        if value.dtype.kind in "OSUV":  # None, a string, a dict...: no numbers
            returned = "None" if action is None else f"a {type(action).__name__}"
            takes = (
                "one integer" if isinstance(space, gym.spaces.Discrete) else f"floats of shape {space.shape}"
            )
            raise PolicyError(
                f"the policy returned {returned} for {self.task}, not an action: its action space {space} "
                f"takes {takes}"
            )
        if isinstance(space, gym.spaces.Discrete):
            if value.size != 1 or value.dtype.kind not in "iu":
                raise PolicyError(
                    f"the policy returned {_show(value)} for {self.task}; its action space {space} takes one "
                    "integer (an int, or an integer array of size 1)"
                )
            index = int(value.reshape(()))
            if not space.contains(index):
                raise PolicyError(f"the policy returned action {index}, outside {self.task}'s {space}")
            return index
        if value.dtype.kind != "f" or value.shape != space.shape:
            raise PolicyError(
                f"the policy returned {_show(value)} for {self.task}; its action space {space} takes a "
                f"float array of shape {space.shape}"
            )
        if not np.all(np.isfinite(value)):
            raise PolicyError(f"the policy returned a non-finite action {value.tolist()} for {self.task}")
        if np.any(value < space.low - 1e-6) or np.any(value > space.high + 1e-6):
            raise PolicyError(
                f"the policy returned {value.tolist()}, outside {self.task}'s action space {space}"
            )
        return value.astype(space.dtype)


def _show(value: np.ndarray) -> str:
    return f"an array of shape {value.shape} and dtype {value.dtype}"


def load_policy(spec: str) -> Callable:
    """The callable ``NAME`` of ``MODULE:NAME``; MODULE is an importable module or a ``.py`` file."""
    import importlib
    import importlib.util
    import sys
    from pathlib import Path

    module_name, _, name = spec.rpartition(":")
    if not module_name or not name:
        raise ValueError(
            f"a policy is MODULE:NAME (e.g. my_agent:policy or agents/mine.py:policy), got {spec!r}"
        )
    try:
        if module_name.endswith(".py"):
            path = Path(module_name)
            if not path.is_file():
                raise ValueError(f"policy file {path} does not exist")
            loader = importlib.util.spec_from_file_location(path.stem, path)
            module = importlib.util.module_from_spec(loader)
            sys.modules[path.stem] = module  # as an import would: dataclasses and pickling look it up
            loader.loader.exec_module(module)
        else:
            module = importlib.import_module(module_name)
    except ImportError as error:
        raise ValueError(f"cannot import the policy's module {module_name!r}: {error}") from None
    policy = getattr(module, name, None)
    if policy is None:
        raise ValueError(f"{module_name} has no {name!r}")
    if not callable(policy):
        raise ValueError(f"{spec} is a {type(policy).__name__}, not a callable (observation -> action)")
    return policy


def as_agent(policy, env: gym.Env, task: str):
    """What :func:`type_sequences` drives: our agents as they are, any other callable checked."""
    return policy if hasattr(policy, "policy_action") else CheckedPolicy(policy, env.action_space, task)


# ------------------------------------------------------------------ fingerprint
def protocol_conditions(
    task: str, protocol: str, sequences, max_episode_steps: int, seed: int, world: dict
) -> dict:
    """Everything that decides a typing score (see the module docstring), JSON-ready."""
    return {
        "fingerprint_format": FINGERPRINT_FORMAT,
        "project_version": __version__,
        "task": task_name(task),
        "protocol": protocol,
        "sequences": [list(s) for s in sequences],
        "max_episode_steps": int(max_episode_steps),
        "start_seed": int(seed),
        "world": {k: v for k, v in json.loads(json.dumps(world)).items() if k != "dataset"},
    }


def fingerprint(conditions: dict) -> str:
    """SHA-256 of the conditions' canonical JSON (sorted keys, no spaces)."""
    text = json.dumps(conditions, sort_keys=True, separators=(",", ":"))
    return hashlib.sha256(text.encode()).hexdigest()


# ------------------------------------------------------------------ bound
def touch_optimum(keys: str, sequences, protocol: str = "released", grid: str = "rig") -> float:
    """Expected fewest steps of any touch-only policy over ``sequences`` on a discrete task's key grid,
    exact over uniform random start cells.

    ``"released"`` (a reset per key): the exact expectation. ``"paper"`` (no
    reset): keys after the first start where the last press left the sensor,
    taken as known, so a lower bound. A policy that reads the images can come
    below it only by luck of the start poses.
    """
    if protocol not in PROTOCOLS:
        raise ValueError(f"protocol must be one of {PROTOCOLS}, got {protocol!r}")
    return _touch_optimum(keys, tuple(map(tuple, sequences)), protocol, grid)


@functools.lru_cache(maxsize=16)
def _touch_optimum(keys: str, sequences: tuple, protocol: str, grid_name: str = "rig") -> float:
    grid = Task(keys, continuous=False, grid=grid_name).key_grid.tolist()
    rows, columns = len(grid), len(grid[0])
    cells = [(r, c) for r in range(rows) for c in range(columns)]

    def move(cell, action):
        dr, dc = _MOVES[action]
        return min(max(cell[0] + dr, 0), rows - 1), min(max(cell[1] + dc, 0), columns - 1)

    @functools.lru_cache(None)
    def steps(belief: tuple, goal: str, depth: int) -> float:
        """Total steps over the cells the sensor may be on (one each), acting on what each move feels."""
        if all(grid[r][c] == goal for r, c in belief):
            return len(belief)  # press
        best = float("inf")
        for action in range(_PRESS) if depth else ():
            felt: dict[str, list] = {}
            for cell in belief:
                after = move(cell, action)
                felt.setdefault(grid[after[0]][after[1]], []).append(after)
            if list(felt.values()) != [list(belief)]:
                total = sum(steps(tuple(sorted(b)), goal, depth - 1) for b in felt.values())
                best = min(best, len(belief) + total)
        return best

    alike: dict[str, list] = {}
    for r, c in cells:
        alike.setdefault(grid[r][c], []).append((r, c))

    def from_start(goal: str) -> float:  # from a uniform random start, on touch alone
        return sum(steps(tuple(b), goal, rows + columns + 2) for b in alike.values()) / len(cells)

    def from_key(key: str, goal: str) -> int:  # from where a press of ``key`` left the sensor, known
        return min(abs(r - q) + abs(c - p) for r, c in alike[key] for q, p in alike[goal]) + 1

    if protocol == "released":
        return float(sum(from_start(goal) for sequence in sequences for goal in sequence))
    return float(sum(from_start(s[0]) + sum(itertools.starmap(from_key, itertools.pairwise(s)))
                     for s in sequences))  # fmt: skip


# ------------------------------------------------------------------ report
@dataclass
class TypingReport:
    """One policy's typing on one task under one protocol (JSON-ready through :meth:`to_dict`)."""

    task: str
    protocol: str
    track: str
    accuracy: float
    total_steps: int
    keys_asked: int
    sequences: int
    fingerprint: str
    conditions: dict = field(repr=False)
    confusion: dict = field(repr=False)
    touch_optimum: float | None = None
    """The discrete tasks' expected touch-only optimum (:func:`touch_optimum`); None for continuous."""
    typing_bound: float | None = None
    """The fewest steps any policy, even one that knows its pose, can type the sequences in
    (:func:`~tactile_braille.evaluation.bounds.typing_bound`: for these start poses under the paper's
    protocol, the expectation with a reset per key); None off the dataset backend."""
    sentences: list[dict] | None = field(default=None, repr=False)

    @property
    def steps_per_key(self) -> float:
        return self.total_steps / max(self.keys_asked, 1)

    def to_dict(self) -> dict:
        return {**asdict(self), "steps_per_key": self.steps_per_key}

    @classmethod
    def from_dict(cls, data: dict) -> TypingReport:
        names = [f.name for f in fields(cls)]
        missing = [f.name for f in fields(cls) if f.default is MISSING and f.name not in data]
        if missing:
            raise ValueError(f"a typing report needs {missing}")
        return cls(**{k: v for k, v in data.items() if k in names})


def evaluate_policy(
    policy,
    task: str,
    *,
    protocol: str = "paper",
    backend: str = "dataset",
    seed: int = 0,
    track: str = "tactile",
    dataset=None,
    max_episode_steps: int | None = None,
    sentences: bool = True,
    env: gym.Env | None = None,
    progress: bool = False,
) -> TypingReport:
    """Type the paper's sequences for ``task`` with ``policy`` and score them (the module docstring).

    ``policy``: a callable from the observation dictionary to an action, or
    one of our agents. ``task``: ``"DiscreteArrows-v0"`` or its full id.
    ``track``: the track the policy competes in (what it learnt from;
    docs/benchmark.md); a ``proprio`` policy's observations also carry the
    arm's pose (``sensor_pose``), a ``tactile`` one's do not. ``env``: an environment of the task to type in
    (one, not a vector environment), instead of one made from ``backend``, ``dataset`` and
    ``max_episode_steps``. Each key's attempt ends at the protocol's episode limit:
    ``max_episode_steps``, or else the task's registered one (25 steps), whatever time limit
    ``env`` has (a longer one, or none, is cut to it; a shorter one is refused). Tasks whose keys
    type text (the alphabet's: their key set's ``types_sentences``) also type :data:`SENTENCES`
    unless ``sentences`` is false. ``progress``: a progress bar of the sequences typed (on stderr).

    Raises:
        TypeError: ``policy`` is not callable, ``task`` not a task's name or ``env`` not one
            ``gym.Env`` (before any environment is made).
        ValueError: an unknown task, protocol or track, an episode limit that is not a positive
            integer, or an ``env`` of another task, of a shorter time limit or (on the tactile track)
            whose observations carry the arm's pose.
    """
    _check_arguments(policy, task, env)
    task_id = task if "/" in task else f"tactile_braille/{task}"
    keys = _task_keys(task_id)
    if protocol not in PROTOCOLS:
        raise ValueError(f"protocol must be one of {PROTOCOLS}, got {protocol!r}")
    if track not in TRACKS:
        raise ValueError(f"track must be one of {TRACKS}, got {track!r}")
    limit = _episode_limit(task_id, max_episode_steps)
    if env is None:
        options = {"backend": backend, "proprio": track == "proprio"}
        options.update({"dataset": dataset} if dataset is not None else {})
        env = gym.make(task_id, **options, max_episode_steps=limit)
    else:
        _check_env(env, task_id, track, limit)
    # The protocol's limit, whatever the environment's own wrapper cuts at (or none, unwrapped).
    env = gym.wrappers.TimeLimit(env, limit)
    agent = as_agent(policy, env, task_name(task_id))
    sequences = paper_sequences(keys)
    grid = env.unwrapped.task.grid  # the key grid the policy types on (the discrete tasks')
    bound = _bound(env, sequences, protocol, seed)
    result = type_sequences(agent, env, sequences, seed=seed, protocol=protocol, progress=progress)
    conditions = protocol_conditions(task_id, protocol, sequences, limit, seed, env.unwrapped.world)
    report = TypingReport(
        task=task_name(task_id), protocol=protocol, track=track, accuracy=result.accuracy,
        total_steps=result.total_steps, keys_asked=sum(map(len, sequences)), sequences=len(sequences),
        fingerprint=fingerprint(conditions), conditions=conditions,
        confusion={"rows": list(result.keys), "columns": list(result.columns),
                   "counts": result.confusion().tolist()},
        touch_optimum=None if task_of(task_id).continuous else touch_optimum(keys, sequences, protocol, grid),
        typing_bound=bound,
    )  # fmt: skip
    if KEY_SETS[keys].types_sentences and sentences:
        report.sentences = type_sentences(agent, env, seed + 1_000)
    return report


def _check_arguments(policy, task, env) -> None:
    """TypeErrors for arguments of the wrong kind (:func:`evaluate_policy`), before anything is made."""
    if not callable(policy) and not hasattr(policy, "policy_action"):
        raise TypeError(f"a policy must be callable (observation -> action), got {type(policy).__name__}")
    if isinstance(task, gym.Env | gym.vector.VectorEnv):
        raise TypeError("task is the task's name (e.g. 'DiscreteArrows-v0'); pass the environment as env=")
    if not isinstance(task, str):
        raise TypeError(f"task must be a task's name (e.g. 'DiscreteArrows-v0'), got {type(task).__name__}")
    if isinstance(env, gym.vector.VectorEnv):
        raise TypeError(f"env is a vector environment of {env.num_envs}; typing is scored in one "
                        "environment: pass one made with gym.make(task)")  # fmt: skip
    if env is not None and not isinstance(env, gym.Env):
        raise TypeError(
            f"env must be a gymnasium.Env of the task (made with gym.make), got {type(env).__name__}"
        )


def _episode_limit(task_id: str, max_episode_steps) -> int:
    """The protocol's episode limit: ``max_episode_steps``, or else the task's registered one."""
    if max_episode_steps is None:
        return gym.spec(task_id).max_episode_steps
    if isinstance(max_episode_steps, bool) or not isinstance(max_episode_steps, int) or max_episode_steps < 1:
        raise ValueError(f"max_episode_steps must be a positive integer or None, got {max_episode_steps!r}")
    return max_episode_steps


def _check_env(env: gym.Env, task_id: str, track: str, limit: int) -> None:
    """ValueErrors for an environment :func:`evaluate_policy` cannot score ``task_id`` in."""
    if env.spec is None:
        raise ValueError(f"the environment has no spec (it was not made with gym.make): make it with "
                         f"gym.make({task_id!r}, ...)")  # fmt: skip
    if task_name(env.spec.id) != task_name(task_id):
        raise ValueError(f"the environment is {env.spec.id}, not {task_id}")
    if env.spec.max_episode_steps is not None and env.spec.max_episode_steps < limit:
        raise ValueError(
            f"the environment's time limit ({env.spec.max_episode_steps} steps) cuts keys short of the "
            f"protocol's {limit}: pass max_episode_steps={env.spec.max_episode_steps} to score under its "
            f"limit, or make it with max_episode_steps={limit}"
        )
    if track == "tactile" and PROPRIO_KEY in env.observation_space.spaces:
        raise ValueError(
            f"a tactile-track policy must not see the arm's pose, but this environment's observations "
            f"carry {PROPRIO_KEY!r} (made with proprio=True): score it as track='proprio' or use a "
            "tactile environment"
        )


def _bound(env: gym.Env, sequences, protocol: str, seed: int) -> float | None:
    """:func:`~tactile_braille.evaluation.bounds.typing_bound` in ``env``'s world (None off the dataset
    backend: the bound is of the paper's simulation; None, with a warning, for a dataset whose grid it cannot
    follow)."""
    from tactile_braille.evaluation.bounds import typing_bound

    dataset = env.unwrapped.dataset
    if dataset is None:
        return None
    try:
        return typing_bound(
            env.spec.id, sequences, protocol, seed, dataset=dataset, grid=env.unwrapped.task.grid
        )
    except ValueError as error:  # a dataset whose grid the bound cannot follow: score without it
        warnings.warn(f"no typing bound for this evaluation: {error}", stacklevel=3)
        return None


def _task_keys(task_id: str) -> str:
    from tactile_braille._registration import ENV_IDS

    if task_id not in ENV_IDS:
        raise ValueError(f"unknown task {task_id.removeprefix('tactile_braille/')!r}; choose one of "
                         f"{[task_name(t) for t in ENV_IDS]}")  # fmt: skip
    return task_of(task_id).keys


def type_sentences(agent, env: gym.Env, seed: int) -> list[dict]:
    """:data:`SENTENCES` typed under the paper's protocol: text typed, accuracy and steps of each."""
    typed = type_sequences(agent, env, [text_keys(s) for s in SENTENCES], seed=seed)
    return [
        {"text": text, "typed": as_text(keys_typed),
         "accuracy": float(np.mean([a == b for a, b in zip(text_keys(text), keys_typed, strict=True)])),
         "steps": int(sum(steps))}
        for text, keys_typed, steps in zip(SENTENCES, typed.typed, typed.steps, strict=True)
    ]  # fmt: skip


def as_text(keys: list[str]) -> str:
    """Typed keys as text: SPACE as a space, a wrong key outside the task or a time-out as ``_``."""
    return "".join(" " if k == "SPACE" else k if len(k) == 1 else "_" for k in keys)
