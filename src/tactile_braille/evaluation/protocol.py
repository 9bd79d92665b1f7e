"""Typing evaluation as in the paper (Section V): sequences of keys, no reset between keys.

Arrows: all 24 permutations of (UP, DOWN, LEFT, RIGHT). Alphabet: 10 random
permutations of the 27 keys (A-Z, SPACE), drawn by :func:`paper_sequences`
with seed 1 (the release drew its own with seed 1 from another generator; the
list we use is in ``docs/evaluation.md``).
The agent acts deterministically; the sensor starts at a random pose once per
sequence and stays where each press left it for the next key. A key counts as
typed right when the first key pressed for it is the goal; a key not pressed
within the episode limit (25 steps; 35 with the released SAC preset) counts as missed, and typing goes on with
the next key from where the sensor is.

The released code's evaluation scripts (``evaluate_model.py``) differ: they
reset the environment, so a fresh random start pose, before **every** key.
``protocol="released"`` types that way (deterministic actions for every
algorithm; the released continuous SAC sampled its actions). Which one the
paper's Table III used: docs/evaluation.md (the evidence favours the
released one).

Metrics: typing accuracy (keys typed right / keys asked), typing efficiency
(total steps over all sequences, the paper's "steps"), and a confusion matrix
(rows: goal key; columns: the task's keys, then ``OTHER`` for a key outside
the task, then ``NONE`` for a time-out).
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass, field

import gymnasium as gym
import numpy as np

from tactile_braille._tasks import KEY_SETS
from tactile_braille.agents.rollout import run_episode
from tactile_braille.keyboard.layout import ALPHABET_KEYS

OTHER, NONE = "OTHER", "NONE"
SENTENCES = (
    "THE QUICK BROWN FOX JUMPS OVER THE LAZY DOG",
    "PACK MY BOX WITH FIVE DOZEN LIQUOR JUGS",
    "SPHINX OF BLACK QUARTZ JUDGE MY VOW",
    "LEARNING TO TYPE ON A BRAILLE KEYBOARD BY TOUCH",
    "A ROBOT READS THE KEYS WITH ITS FINGERTIP BEFORE IT PRESSES ONE",
)
"""Pangrams and ordinary sentences for the alphabet tasks (spaces typed as SPACE)."""


def paper_sequences(keys: str, count: int | None = None, seed: int = 1) -> list[tuple[str, ...]]:
    """The evaluation sequences of key set ``keys``, as its row of :data:`~tactile_braille._tasks.KEY_SETS`
    says (``typing_sequences``): every permutation of its keys (the arrows' 24), or ``count`` random
    permutations drawn with ``seed`` (None: the row's number, the alphabet's 10)."""
    if keys not in KEY_SETS:
        raise ValueError(f"keys must be one of {sorted(KEY_SETS)}, got {keys!r}")
    row = KEY_SETS[keys]
    if row.typing_sequences is None:
        return list(itertools.permutations(row.keys))
    rng = np.random.default_rng(seed)
    count = row.typing_sequences if count is None else count
    return [tuple(row.keys[i] for i in rng.permutation(len(row.keys))) for _ in range(count)]


def text_keys(text: str) -> tuple[str, ...]:
    """The keys that type ``text`` (letters and spaces only)."""
    keys = []
    for character in text.upper():
        if character == " ":
            keys.append("SPACE")
        elif character in ALPHABET_KEYS:
            keys.append(character)
        else:
            raise ValueError(f"cannot type {character!r}: the alphabet tasks have A-Z and SPACE")
    return tuple(keys)


@dataclass
class TypingResult:
    """What typing a list of sequences gave."""

    keys: tuple[str, ...]
    sequences: list[tuple[str, ...]]
    typed: list[list[str]] = field(default_factory=list)
    steps: list[list[int]] = field(default_factory=list)

    @property
    def accuracy(self) -> float:
        """Keys typed right, as a share of the keys asked."""
        pairs = [(g, t) for sequence, typed in zip(self.sequences, self.typed, strict=True)
                 for g, t in zip(sequence, typed, strict=True)]  # fmt: skip
        return float(np.mean([g == t for g, t in pairs])) if pairs else float("nan")

    @property
    def total_steps(self) -> int:
        """Steps over all sequences (the paper's typing efficiency)."""
        return int(sum(sum(s) for s in self.steps))

    @property
    def columns(self) -> tuple[str, ...]:
        return (*self.keys, OTHER, NONE)

    def confusion(self) -> np.ndarray:
        """Counts, rows: goal key (task order); columns: :attr:`columns`."""
        matrix = np.zeros((len(self.keys), len(self.columns)), dtype=np.int64)
        for sequence, typed in zip(self.sequences, self.typed, strict=True):
            for goal, pressed in zip(sequence, typed, strict=True):
                matrix[self.keys.index(goal), self.columns.index(pressed)] += 1
        return matrix

    def summary(self) -> dict:
        return {
            "sequences": len(self.sequences),
            "keys_asked": int(sum(len(s) for s in self.sequences)),
            "accuracy": self.accuracy,
            "total_steps": self.total_steps,
            "steps_per_key": self.total_steps / max(sum(len(s) for s in self.sequences), 1),
        }


PROTOCOLS = ("paper", "released")
"""Typing protocols: the paper's (no reset between keys) and the released code's (a reset per key)."""


def type_sequences(
    agent,
    env: gym.Env,
    sequences: list[tuple[str, ...]],
    seed: int = 0,
    protocol: str = "paper",
    progress: bool = False,
) -> TypingResult:
    """Type each sequence with the agent's test-time actions (see the module docstring).

    ``env`` is a braille environment made with ``gym.make`` (its time limit
    cuts each key's attempt). ``protocol``: ``"paper"`` keeps the sensor where
    each press left it; ``"released"`` starts every key from a random pose.
    ``progress``: a progress bar of the sequences typed (on stderr).
    """
    if protocol not in PROTOCOLS:
        raise ValueError(f"protocol must be one of {PROTOCOLS}, got {protocol!r}")
    keys = tuple(env.unwrapped.goal_keys)
    for sequence in sequences:
        unknown = set(sequence) - set(keys)
        if unknown:
            raise ValueError(f"keys {sorted(unknown)} are not among the task's keys {keys}")
    rng = np.random.default_rng(seed)
    result = TypingResult(keys=keys, sequences=[tuple(s) for s in sequences])
    numbered = enumerate(result.sequences)
    if progress:
        from tqdm.auto import tqdm

        numbered = tqdm(numbered, total=len(sequences), desc=f"typing {protocol}", unit="sequence")
    for number, sequence in numbered:
        typed, steps = [], []
        for position, goal in enumerate(sequence):
            episode = run_episode(
                agent, env, rng, seed=seed + number if position == 0 else None,
                options={"goal_key": goal, "keep_pose": position > 0 and protocol == "paper"},
                deterministic=True,
            )  # fmt: skip
            pressed = NONE
            if episode.terminated:
                pressed = episode.info["pressed_key"] if episode.info["pressed_key"] in keys else OTHER
            typed.append(pressed)
            steps.append(episode.steps)
        result.typed.append(typed)
        result.steps.append(steps)
    return result
