"""A metric key map for the planner on the continuous tasks: where on the keyboard a frame was tapped,
learnt from touch and the run's own moves alone.

The key graph (:mod:`~tactile_braille.agents.planner`) knows which key is under the sensor, not where
on it: it types a key by moves of a fixed length and a press, three steps a key on the arrows where
one move that ends in a press would do. The locator adds the where:

* **a key map**, ``centres[key]``, a point per key (the actions' units: 1 is the task's largest move),
  and **an offset reader**, a small CNN that reads from a frame where on its key it was tapped (a tap
  at the same place on two keys looks nearly alike; within a key, taps 1 mm apart differ). A frame
  read as ``key`` is at ``centres[key] + offset(frame)``.
* Both are fitted on **pairs of frames of one episode** whose keys are known (the planner's labels,
  else what its reader reads with ``locate_accept``; never a press's deep frame) with the sum of the
  commanded moves between them (the previous actions, in the observations): ``position(b) -
  position(a) = moves``, a Huber loss (a move that meets the workspace's edge moves less than
  commanded). No pose is read: the map's origin is arbitrary.
* **Press points**: where each press of the replay was made, placed by the last frame of its episode
  the map places and the moves since, and what it pressed. A key's *targets* are its own press points,
  each with its *safety*, the distance to the nearest press point that pressed anything else.

Acting (:func:`locate_action`), it aims at the goal's target that the fewest steps reach (a step
moves up to 1 along x and along y) among those at least ``margin`` safe, the safest of them, and
moves there, with a press in the step that reaches it.
"""

from __future__ import annotations

import math

import numpy as np
import torch
from torch import nn
from torch.nn import functional as F

TARGETS = 256
"""Press points kept per key as its targets: the safest in each cell of :data:`TARGET_CELL`, the safest
cells first."""
TARGET_CELL = 0.1
"""Side of the cells a key's press points are thinned in (the actions' units)."""


class KeyLocator(nn.Module):
    """The key map and the offset reader (module docs); ``targets``/``safety`` the press points
    (keys, TARGETS, 2) and their safety (keys, TARGETS), NaN and -inf where a key has fewer."""

    def __init__(self, keys: int, hidden: tuple[int, ...] = (128,)) -> None:
        super().__init__()
        from tactile_braille.agents.planner import KeyReader  # the same trunk, two outputs

        self.offsets = KeyReader(2, hidden)
        self.centres = nn.Parameter(torch.zeros(keys, 2))
        self.register_buffer("targets", torch.full((keys, TARGETS, 2), math.nan))
        self.register_buffer("safety", torch.full((keys, TARGETS), -math.inf))
        self.register_buffer("separation", torch.zeros(()))  # press_separation of the targets' presses

    def forward(self, frames: torch.Tensor, keys: torch.Tensor) -> torch.Tensor:
        """Positions (B, 2) of frames (B, 1, H, W) read as ``keys`` (B,)."""
        return self.centres[keys] + self.offsets(frames)


def frame_pairs(
    rows: np.ndarray, labels: np.ndarray, deltas: np.ndarray, firsts: np.ndarray, span: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Pairs of frames of one episode, both with a key's class, and the moves between them.

    Args:
        rows: (transitions, 2) each transition's two frames, in replay order.
        labels: each frame's class (-1 unknown; a key below ``keys``, anything else not a key).
        deltas: (transitions, 2) each transition's commanded move (a press: none).
        firsts: which transitions begin an episode.
        span: the most transitions a pair spans.

    Returns:
        ``(first frames, second frames, moves)`` of the pairs.
    """
    firsts = np.asarray(firsts, bool)
    episode = np.cumsum(firsts)
    moved = np.cumsum(np.r_[np.zeros((1, 2)), deltas], axis=0)  # the moves before each transition
    a, b, d = [], [], []
    for length in range(1, span + 1):
        if length > len(rows):
            break
        start = np.arange(len(rows) - length + 1)
        last = start + length - 1
        same = episode[start] == episode[last]
        a.append(rows[start[same], 0])
        b.append(rows[last[same], 1])
        d.append(moved[last[same] + 1] - moved[start[same]])
    first, second = np.concatenate(a), np.concatenate(b)
    moves = np.concatenate(d).astype(np.float32)
    keep = (labels[first] >= 0) & (labels[second] >= 0)
    return first[keep], second[keep], moves[keep]


def locator_loss(
    locator: KeyLocator, first: torch.Tensor, second: torch.Tensor, keys: torch.Tensor,
    moves: torch.Tensor, huber: float = 0.05,
) -> torch.Tensor:  # fmt: skip
    """The pairs' Huber loss on ``position(second) - position(first) - moves`` (``keys`` (B, 2): the
    two frames' keys), and a small pull of the map's mean to 0 (its origin is free)."""
    positions = locator(torch.cat([first, second]), torch.cat([keys[:, 0], keys[:, 1]]))
    before, after = positions.float().chunk(2)
    loss = F.huber_loss(after - before, moves, delta=huber)
    return loss + 1e-3 * locator.centres.mean(0).square().sum()


def press_points(
    positions: np.ndarray, located: np.ndarray, rows: np.ndarray, deltas: np.ndarray,
    firsts: np.ndarray, pressed: np.ndarray, outcomes: np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:  # fmt: skip
    """Where each press was made and what it pressed.

    Each frame the map places (``located``; ``positions`` (frames, 2)) is where the map says; a frame it
    does not is the last placed frame of its episode and the moves since (unknown if none came before).

    Args:
        positions, located: the map's position of each frame and whether it places it.
        rows: (transitions, 2) each transition's frames; deltas: (transitions, 2) its moves.
        firsts: each episode's first transition; pressed: which transitions press; outcomes: the key
            each pressed (-1: anything else).

    Returns:
        ``(points (presses, 2), outcomes (presses,))`` of the presses that were placed.
    """
    points, kinds = [], []
    where = None
    for step in range(len(rows)):
        if firsts[step]:
            where = None
        this = rows[step, 0]
        if located[this]:
            where = positions[this]
        if pressed[step] and where is not None:
            points.append(where + deltas[step])
            kinds.append(outcomes[step])
        after = rows[step, 1]
        where = positions[after] if located[after] else (None if where is None else where + deltas[step])
    if not points:
        return np.zeros((0, 2)), np.zeros(0, np.int64)
    return np.array(points), np.array(kinds, np.int64)


def key_targets(points: np.ndarray, outcomes: np.ndarray, keys: int) -> tuple[np.ndarray, np.ndarray]:
    """Each key's targets (keys, TARGETS, 2) and their safety (keys, TARGETS): its press points, each
    with the distance to the nearest press point of any other outcome (``inf`` if none), thinned to the
    safest in each :data:`TARGET_CELL` cell and then to the safest :data:`TARGETS` (NaN and -inf to
    fill)."""
    targets = np.full((keys, TARGETS, 2), np.nan)
    safety = np.full((keys, TARGETS), -np.inf)
    for key in range(keys):
        own, others = points[outcomes == key], points[outcomes != key]
        if len(own) == 0:
            continue
        distance = nearest(own, others)[0]
        order = np.argsort(-distance, kind="stable")
        _, first = np.unique(np.floor(own[order] / TARGET_CELL), axis=0, return_index=True)
        order = order[np.sort(first)][:TARGETS]  # the safest of each cell, safest cells first
        targets[key, : len(order)], safety[key, : len(order)] = own[order], distance[order]
    return targets, safety


def press_separation(points: np.ndarray, outcomes: np.ndarray) -> float:
    """The share of the presses of a key (``outcomes`` >= 0) whose nearest other press point had the
    same outcome (leave one out): how well the map tells the keys apart where it places the presses.
    0 with fewer than two presses."""
    keyed = np.flatnonzero(outcomes >= 0)
    if len(points) < 2 or len(keyed) == 0:
        return 0.0
    _, index = nearest(points[keyed], points, exclude=keyed)
    return float(np.mean(outcomes[index] == outcomes[keyed]))


def nearest(queries: np.ndarray, points: np.ndarray, exclude: np.ndarray | None = None, chunk: int = 1024):
    """The distance to the nearest of ``points`` (M, 2) from each of ``queries`` (N, 2) and its index
    (``inf`` and -1 if there are none); ``exclude[i]``: a point query ``i`` may not take (itself)."""
    distance, index = np.full(len(queries), np.inf), np.full(len(queries), -1)
    if len(points) == 0:
        return distance, index
    table = torch.as_tensor(points, dtype=torch.float64)
    for start in range(0, len(queries), chunk):
        rows = slice(start, start + chunk)
        d = torch.cdist(torch.as_tensor(queries[rows], dtype=torch.float64), table)
        if exclude is not None:
            d[torch.arange(len(d)), torch.as_tensor(exclude[rows])] = math.inf
        best = d.min(1)
        distance[rows], index[rows] = best.values.numpy(), best.indices.numpy()
    return distance, index


def steps_to(offsets: np.ndarray) -> np.ndarray:
    """The fewest steps that move by each of ``offsets`` (..., 2), a step moving up to 1 along each axis
    (at least one: the press)."""
    return np.maximum(np.ceil(np.abs(offsets).max(-1) - 1e-6), 1)


def locate_action(
    where: np.ndarray, targets: np.ndarray, safety: np.ndarray, margin: float,
) -> tuple[np.ndarray, bool] | None:  # fmt: skip
    """The move (2,) toward the goal's best target from ``where``, and whether it ends there (then
    the step presses); None if the goal has no target.

    The best target: of those at least ``margin`` safe (all, if none is), the fewest steps away, and
    of those the safest. The move goes the whole way if one step reaches it, else an equal share of
    the steps."""
    valid = np.isfinite(safety)
    if not valid.any():
        return None
    targets, safety = targets[valid], safety[valid]
    safe = safety >= margin
    if safe.any():
        targets, safety = targets[safe], safety[safe]
    steps = steps_to(targets - where)
    fewest = steps == steps.min()
    best = np.flatnonzero(fewest)[np.argmax(safety[fewest])]
    count = int(steps[best])
    return (targets[best] - where) / count, count == 1
