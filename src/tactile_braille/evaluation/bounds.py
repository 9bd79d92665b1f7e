"""The fewest typing steps the simulated world allows: a lower bound on the steps of any policy that
types every key right, even one that knows the sensor's pose and the key layout exactly (a policy
that presses wrong keys can take fewer).

:func:`typing_bound` computes it from the world itself (the dataset backend, the paper's
simulation), for the sequences and start poses of a typing evaluation
(:func:`~tactile_braille.evaluation.protocol.type_sequences`):

* **Discrete tasks.** A move goes to a neighbouring cell of the key grid (a
  move off the grid stays), so the fewest moves between two cells is their
  Manhattan distance; a key is typed by one more step, PRESS, on one of its
  cells. With no reset between keys (the paper's protocol) the cell each key
  is pressed at decides where the next key starts (SPACE has six): dynamic
  programming over the sequence picks the best, from the start cell the
  evaluation's seed draws. Exact.
* **Continuous tasks.** A step moves the sensor by up to the task's largest
  move in x and in y (a box; the position stays in the workspace) and taps
  at any depth in [2, 8] mm; the tap presses what the stored grid sample
  nearest to it pressed. The workspace is rasterised at :data:`RASTER_MM`
  into half-open cells, whose edges fall on the samples' rounding edges; a
  key's *press region* is every cell a tap at some depth presses it in, grown
  by one cell (a point on a cell's edge may round to the neighbour). The
  places the sensor can have pressed each key after a given number of steps
  are cell masks: the last masks grown by the moves (exactly: a cell grown by
  a move is a whole number of cells), intersected with the key's region, from
  the evaluation's start pose. Each mask holds every point the sensor can
  truly be at, so the count is never above the true fewest: a lower bound,
  loose by at most the regions' one-cell margin (0.5 mm) per key.

**A margin** (``margin_mm``, continuous tasks): the same count when every
press must land at least that far inside its key's press region, that is
where every point of the raster within ``margin_mm`` presses the same key at
some depth (the region shrunk by that many cells, not grown). A policy that
knows the pose to the millimetre cannot count on pressing at a region's very
edge on a rig, nor can one that estimates its pose from touch: the bound with
a margin is what such a policy can at best hope for.

With a reset per key (``protocol="released"``) each key starts from a fresh
random pose. On the continuous tasks those are drawn from the generator the
sequence's seed starts, which nothing else draws from on the dataset
backend: the bound is for those starts, as above. On the discrete tasks the
taps draw their stored images from the same generator, so the starts depend
on the policy's own steps: the bound is then the *expected* fewest steps over
uniformly random starts (exact), and a policy can come below it by luck.

:class:`KeyByKeyTypist` types the continuous tasks with the pose and the same
press regions, but one key at a time, as a policy must: it does not know the
next key. Its steps lie between the bound and the centre-seeking script.

The same script with the pose gives an upper yardstick
(``benchmarks/typing_bounds.py`` prints both, and the touch-only optimum).

>>> round(typing_bound("DiscreteArrows-v0", [("UP", "DOWN")], protocol="released"), 3)
4.333
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
from gymnasium.utils import seeding
from scipy import ndimage

from tactile_braille.envs.backends import DatasetBackend
from tactile_braille.envs.core import OBSERVATION_SIZE_PX, BatchedBraille
from tactile_braille.envs.registry import task_of
from tactile_braille.envs.tasks import Task
from tactile_braille.evaluation.protocol import PROTOCOLS, paper_sequences
from tactile_braille.keyboard.layout import KeyboardLayout

RASTER_MM = 0.5
"""Side of the raster cells of the continuous workspace (a divisor of the grids' half-spacings and of
the workspaces' sides, so the raster cells' edges fall on the press regions' edges)."""


def typing_bound(
    task: str,
    sequences: Sequence[Sequence[str]] | None = None,
    protocol: str = "paper",
    seed: int = 0,
    dataset=None,
    grid: str = "rig",
    margin_mm: float = 0.0,
) -> float:
    """The fewest steps any policy can type ``sequences`` in on ``task``'s dataset backend (module docs).

    ``sequences`` default to the paper's evaluation sequences; ``seed`` is the
    typing evaluation's seed (sequence ``i`` starts from the pose that
    ``reset(seed=seed + i)`` draws). ``protocol="paper"``: for those starts;
    ``"released"``: for the starts the resets draw (continuous tasks), or the
    expectation over uniformly random starts (discrete tasks). ``grid``: the discrete tasks' key grid
    (``"rig"`` or the released simulator's, ``"released"``). ``margin_mm``: on the continuous tasks,
    presses land at least this far inside their key's press region (a multiple of :data:`RASTER_MM`;
    0: anywhere in it, its edges included).
    """
    task_id = task if "/" in task else f"tactile_braille/{task}"
    spec = task_of(task_id)
    if spec is None:
        raise ValueError(f"typing_bound is for the braille tasks, got {task!r}")
    spec = Task(spec.keys, spec.continuous, grid=grid)
    sequences = paper_sequences(spec.keys) if sequences is None else [tuple(s) for s in sequences]
    if margin_mm and not spec.continuous:
        raise ValueError(f"margin_mm is for the continuous tasks' press regions; {task} moves on a grid")
    cells = margin_cells(margin_mm)
    where = None if dataset is None else str(getattr(dataset, "path", dataset))
    key = (task_id, tuple(sequences), protocol, seed, where, grid, cells)
    if key not in _BOUNDS:
        _BOUNDS[key] = _typing_bound(task_id, spec, sequences, protocol, seed, dataset, cells)
    return _BOUNDS[key]


def margin_cells(margin_mm: float) -> int:
    """A press margin in raster cells; a ValueError unless it is a multiple of :data:`RASTER_MM`, >= 0."""
    cells = margin_mm / RASTER_MM
    if not (margin_mm >= 0 and math.isclose(cells, round(cells), abs_tol=1e-9)):
        raise ValueError(f"margin_mm must be a multiple of {RASTER_MM} mm, at least 0, got {margin_mm}")
    return round(cells)


_BOUNDS: dict[tuple, float] = {}
"""Bounds computed in this process, by task, sequences, protocol, seed, dataset path, key grid and margin
(in raster cells)."""


def _typing_bound(
    task_id: str, spec, sequences: list[tuple[str, ...]], protocol: str, seed: int, dataset, margin: int
):
    if protocol not in PROTOCOLS:
        raise ValueError(f"protocol must be one of {PROTOCOLS}, got {protocol!r}")
    unknown = sorted({key for s in sequences for key in s} - set(spec.goal_keys))
    if unknown:
        raise ValueError(f"keys {unknown} are not among {task_id}'s keys {spec.goal_keys}")
    # The evaluation's start poses come from its seeds alone: a core whose taps read no images draws
    # them exactly as the environment's reset does (goal, then pose, from the seeded generator).
    layout = KeyboardLayout()
    core = BatchedBraille(spec, _Blind(layout), 1)
    if spec.continuous:
        world = _ContinuousWorld(spec, DatasetBackend(spec, dataset, layout=layout), core, margin)
    else:
        world = _GridWorld(spec, core)
    total = 0.0
    everywhere = np.ones(1, dtype=bool)
    for number, sequence in enumerate(sequences):
        if not sequence:
            continue
        rng = seeding.np_random(seed + number)[0]  # the evaluation's first reset of the sequence
        if protocol == "paper":
            core.reset(everywhere, rng)
            total += world.fewest_steps(sequence)
        elif spec.continuous:  # a reset per key, all drawn from the sequence's generator (taps draw nothing)
            for goal in sequence:
                core.reset(everywhere, rng)
                total += world.fewest_steps((goal,))
        else:  # discrete taps draw their stored images from the same generator: starts are not known
            total += math.fsum(world.expected_from_anywhere(goal) for goal in sequence)
    return round(total, 6)


class _Blind:
    """A backend that reads nothing: blank images, no key pressed (for drawing start poses)."""

    def __init__(self, layout: KeyboardLayout) -> None:
        self.layout = layout

    def discrete_taps(self, codes, press, positions_mm, rng):
        return np.zeros((len(codes), OBSERVATION_SIZE_PX, OBSERVATION_SIZE_PX), np.uint8), np.full(
            len(codes), -1
        )

    def continuous_taps(self, x_mm, y_mm, depth_mm, rng):
        return self.discrete_taps(x_mm, None, None, rng)


class _GridWorld:
    """Discrete tasks: cells of the key grid, Manhattan moves, one PRESS per key."""

    def __init__(self, task: Task, core: BatchedBraille) -> None:
        self.core = core
        grid = task.key_grid
        self.cells = np.argwhere(np.ones(grid.shape, dtype=bool))
        self.cells_of = {key: np.argwhere(grid == key) for key in task.goal_keys}

    def fewest_steps(self, sequence: Sequence[str]) -> int:
        """From the sensor's cell now: the fewest steps over the sequence (best press cell per key)."""
        at, cost = self.core.cell[:1].copy(), np.zeros(1, dtype=np.int64)
        for goal in sequence:
            targets = self.cells_of[goal]
            moves = np.abs(at[:, None, :] - targets[None, :, :]).sum(axis=-1)  # (from, to)
            at, cost = targets, (cost[:, None] + moves + 1).min(axis=0)
        return int(cost.min())

    def expected_from_anywhere(self, goal: str) -> float:
        targets = self.cells_of[goal]
        moves = np.abs(self.cells[:, None, :] - targets[None, :, :]).sum(axis=-1).min(axis=1)
        return float(np.mean(moves + 1))


class _ContinuousWorld:
    """Continuous tasks on the dataset backend: raster masks of where the sensor can be."""

    def __init__(self, task: Task, backend: DatasetBackend, core: BatchedBraille, margin: int = 0) -> None:
        self.core = core
        (x0, x1), (y0, y1) = task.workspace_mm
        self.low = np.array([x0, y0])
        shape = (round((x1 - x0) / RASTER_MM), round((y1 - y0) / RASTER_MM))
        origin = np.array(task.frame_origin_mm)
        step = backend._grid_step[:2]
        edges = (backend._grid_start[:2] - origin - step / 2 - self.low) / RASTER_MM  # first cell edges
        for what, cells in (("the workspace's sides", np.array([x1 - x0, y1 - y0]) / RASTER_MM),
                            ("the largest move", np.array([task.max_move_mm]) / RASTER_MM),
                            ("the dataset grid's spacing", step / RASTER_MM),
                            ("the dataset grid's cell edges", edges)):  # fmt: skip
            if not np.allclose(cells, np.round(cells), atol=1e-6):
                raise ValueError(f"{what} do not fall on the {RASTER_MM} mm raster: no exact bound here")
        self.move_cells = round(task.max_move_mm / RASTER_MM)
        self.max_moves = math.ceil(max(shape) / self.move_cells)  # enough to cross the workspace
        centres = [self.low[i] + origin[i] + (np.arange(shape[i]) + 0.5) * RASTER_MM for i in range(2)]
        x, y = np.meshgrid(*centres, indexing="ij")
        pressed = np.stack([backend.pressed_codes(x, y, depth) for depth in backend.grid_depths_mm])
        layout = backend.layout
        regions = {key: (pressed == layout.key(key).index).any(axis=0) for key in task.goal_keys}
        empty = [key for key, region in regions.items() if not region.any()]
        if empty:
            raise ValueError(f"no tap in the workspace presses {empty}: the dataset cannot type them")
        # A raster cell is half-open, [x, x + r) x [y, y + r), and wholly on one side of the samples'
        # rounding edges, but for its left and lower edges: a point on one of those may round to the
        # neighbouring sample. Growing each region by one cell takes such points in.
        self.pressing = regions  # the cells whose centre presses each key
        if margin:  # the cells whose every neighbour within the margin presses the key
            self.regions = {key: ~_dilate(~region, margin) for key, region in regions.items()}
        else:
            self.regions = {key: _dilate(region, 1) for key, region in regions.items()}
        emptied = [key for key, region in self.regions.items() if not region.any()]
        if emptied:
            raise ValueError(f"no press lands {margin * RASTER_MM} mm inside the regions of {emptied}")

    def _reach(self, mask: np.ndarray, moves: int) -> np.ndarray:
        """The cells holding every point within ``moves`` steps of a point of ``mask``'s cells (a cell
        [x, x + r) grown by m on each side is exactly the cells from x - m to x + r + m)."""
        return _dilate(mask, moves * self.move_cells)

    def fewest_steps(self, sequence: Sequence[str]) -> int:
        """From the sensor's position now: the fewest steps over the sequence (a lower bound)."""
        start = np.zeros(next(iter(self.regions.values())).shape, dtype=bool)
        cell = np.floor((self.core.position_mm[0] - self.low) / RASTER_MM).astype(int)
        start[tuple(np.clip(cell, 0, np.array(start.shape) - 1))] = True  # the far edge: the last cell
        frontier = [(0, start)]  # (steps so far, raster cells the sensor can be in)
        for goal in sequence:
            reached: dict[int, np.ndarray] = {}
            for steps, mask in frontier:
                for moves in range(1, self.max_moves + 1):
                    here = self._reach(mask, moves) & self.regions[goal]
                    if here.any():
                        reached[steps + moves] = reached.get(steps + moves, False) | here
            frontier = self._undominated(sorted(reached.items()))
        return frontier[0][0]

    def _undominated(self, entries: list[tuple[int, np.ndarray]]) -> list[tuple[int, np.ndarray]]:
        """Drop an entry whose cells all lie within its extra steps' moves of a cheaper entry's: any
        way on from it is as short from there (reaches add up exactly: growing by a then by b cells is
        growing by a + b)."""
        kept: list[tuple[int, np.ndarray]] = []
        for steps, mask in entries:
            if not any(not (mask & ~self._reach(k_mask, steps - k_steps)).any() for k_steps, k_mask in kept):
                kept.append((steps, mask))
        return kept


class KeyByKeyTypist:
    """A pose-aware typist for the continuous tasks that types one key at a time, as a policy must.

    It knows the sensor's pose and the press regions :func:`typing_bound` counts on (so it is a
    yardstick, not a baseline), but not the next key. It presses ``margin_mm`` inside the goal's
    region, where that key's steps plus the mean fewest steps from there to each of the other keys (the
    next key asked: the paper's sequences never repeat one) are fewest; on the way it moves as far as a
    step goes towards that place with a light tap, and plans again after every step. It acts through
    the agents' interface (``policy_action``), so the typing evaluation counts its steps.

    Args:
        env: a continuous braille environment on the dataset backend (wrapped or not).
        margin_mm: how far inside its key's press region each press lands (a multiple of
            :data:`RASTER_MM`).
    """

    def __init__(self, env, margin_mm: float = 1.0) -> None:
        braille = env.unwrapped
        backend = braille._core.backend
        if not braille.task.continuous or not isinstance(backend, DatasetBackend):
            raise ValueError(
                f"the key-by-key typist reads the press regions of a continuous task's dataset backend, "
                f"got {braille.task.keys} ({'continuous' if braille.task.continuous else 'discrete'}) on "
                f"{type(backend).__name__}"
            )
        self.env, self.braille = env, braille
        margin = margin_cells(margin_mm)
        self.world = _ContinuousWorld(braille.task, backend, braille._core, margin)
        regions = self.world.regions if margin else self.world.pressing  # cells whose centre presses
        move = self.world.move_cells
        reach = {}  # the fewest steps from each raster cell to a press of each key
        for key, region in regions.items():
            distance = ndimage.distance_transform_cdt(~region, metric="chessboard")
            reach[key] = np.maximum(1, np.ceil(distance / move))
        self.places = {key: np.argwhere(region) for key, region in regions.items()}
        self.after = {  # at each place of a key's region: the mean fewest steps to the next key
            key: np.mean([reach[other] for other in reach if other != key], axis=0)[tuple(places.T)]
            for key, places in self.places.items()
        }

    def policy_action(self, observation, step, explore, rng, deterministic=False) -> np.ndarray:
        braille, world = self.braille, self.world
        core, task = braille._core, braille.task
        goal = braille.goal_keys[int(core.goal[0])]
        centres = world.low + (self.places[goal] + 0.5) * RASTER_MM
        offsets = centres - core.position_mm[0]
        steps = np.maximum(1, np.ceil(np.abs(offsets).max(axis=1) / task.max_move_mm - 1e-9))
        best = int(np.argmin(steps + self.after[goal]))
        move = offsets[best] / task.max_move_mm
        if steps[best] > 1:  # not within reach: as far as a step goes, tapping lightly
            return np.array([*np.clip(move, -1, 1), -1.0], dtype=np.float32)
        x, y = centres[best] + task.frame_origin_mm
        depths = core.backend.grid_depths_mm
        code = braille.layout.key(goal).index
        depth = depths[np.flatnonzero(core.backend.pressed_codes(x, y, depths) == code)[-1]]  # the deepest
        low, high = task.depth_range_mm
        return np.array([*move, (depth - (low + high) / 2) / ((high - low) / 2)], dtype=np.float32)


def _dilate(mask: np.ndarray, cells: int) -> np.ndarray:
    """``mask`` grown by ``cells`` raster cells along both axes (a square of side 2 * cells + 1)."""
    out = mask
    for axis in (0, 1):
        padded = np.moveaxis(out, axis, 0)
        padded = np.concatenate([np.zeros((cells, *padded.shape[1:]), dtype=bool), padded])
        span, length = 1, 2 * cells + 1  # padded[i] becomes the OR of padded[i : i + span]
        while span < length:
            shift = min(span, length - span)
            padded[:-shift] |= padded[shift:]
            span += shift
        out = np.moveaxis(padded[: out.shape[axis]], 0, axis)
    return out
