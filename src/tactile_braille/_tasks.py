"""The braille tasks as data: a row per key set and a row per registered environment id.

Every layer reads these rows rather than asking which key set a task types:
registration (:mod:`tactile_braille._registration` registers one id per row of
:data:`REGISTERED_TASKS`), the keyboard (the key sets), the datasets (the
paper's stored grid over each workspace), the environments (key grids, move
bound, workspace, work frame), the presets and the evaluation (typing
sequences, report labels). A new key set or task is a new row here.

Plain data, read by ``import tactile_braille``: this module imports nothing but
the standard library. The numbers are the paper's (``docs/environments.md``).

>>> KEY_SETS["arrows"].max_move_mm, KEY_SETS["alphabet"].workspace_mm
(10.0, ((-30.0, 30.0), (-90.0, 90.0)))
>>> [(task.name, task.keys, task.continuous) for task in REGISTERED_TASKS][-1]
('ContinuousAlphabet-v0', 'alphabet', True)
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

KeyGridRows = tuple[tuple[str, ...], ...]

MAX_EPISODE_STEPS = 25
"""Episode cut (the registry's ``max_episode_steps``), as in the paper."""

_NONE = "NONE"  # a cell off the keys (:data:`tactile_braille.keyboard.layout.NONE_KEY`)


@dataclass(frozen=True, eq=False)
class KeySet:
    """One key set and what its tasks need to know of it.

    Attributes:
        name: the environments' ``keys`` argument (``"arrows"``, ``"alphabet"``).
        keys: the keys a goal is drawn from, in the order of the goal one-hots.
        key_grids: the discrete tasks' key grids by name (the environments' ``key_grid``): ``"rig"``,
            the original robot's, and ``"released"``, the released simulator's; rows of key names,
            ``NONE`` for a cell off the keys, a key over several cells (SPACE) named in each.
        max_move_mm: bound of a continuous move along x and along y.
        workspace_mm: the continuous tasks' workspace, ``((x_low, x_high), (y_low, y_high))`` in
            their work frame.
        work_frame: the real robot's activation map whose calibrated frame is the continuous tasks'
            work frame (:data:`tactile_braille.keyboard.calibration.CALIBRATED_FRAMES`).
        grid_spacing_mm, grid_depth_step_mm: the paper's stored grid of taps over the workspace (the
            continuous tasks' dataset backend: :class:`tactile_braille.datasets.procedures.GridTaps`).
        typing_sequences: the typing evaluation's sequences: None, every permutation of the keys;
            a number, that many random permutations
            (:func:`tactile_braille.evaluation.protocol.paper_sequences`).
        types_sentences: the keys type text (A-Z and SPACE): the typing evaluation also types sentences.
    """

    name: str
    keys: tuple[str, ...]
    key_grids: Mapping[str, KeyGridRows]
    max_move_mm: float
    workspace_mm: tuple[tuple[float, float], tuple[float, float]]
    work_frame: str
    grid_spacing_mm: float
    grid_depth_step_mm: float
    typing_sequences: int | None
    types_sentences: bool


_ARROWS_GRID: KeyGridRows = ((_NONE, "UP", _NONE), ("LEFT", "DOWN", "RIGHT"))
_ALPHABET_ROWS: KeyGridRows = (tuple("QWERTYUIOP"), (*"ASDFGHJKL", _NONE))
_SPACE_ROW = (_NONE, _NONE, *(["SPACE"] * 6), _NONE, _NONE)

KEY_SETS: dict[str, KeySet] = {
    "arrows": KeySet(
        name="arrows",
        keys=("UP", "DOWN", "LEFT", "RIGHT"),
        key_grids={"rig": _ARROWS_GRID, "released": _ARROWS_GRID},
        max_move_mm=10.0,
        workspace_mm=((-20.0, 0.0), (-20.0, 20.0)),
        work_frame="arrows",
        grid_spacing_mm=1.0,
        grid_depth_step_mm=0.5,
        typing_sequences=None,  # all 24
        types_sentences=False,
    ),
    "alphabet": KeySet(
        name="alphabet",
        keys=(*"ABCDEFGHIJKLMNOPQRSTUVWXYZ", "SPACE"),
        key_grids={
            # The robot's third row starts under A; the released simulator's one column right, Z under S
            # (its envs/sim/disc_sim_braille_env/mock_kb.py).
            "rig": (*_ALPHABET_ROWS, (*"ZXCVBNM", _NONE, _NONE, _NONE), _SPACE_ROW),
            "released": (*_ALPHABET_ROWS, (_NONE, *"ZXCVBNM", _NONE, _NONE), _SPACE_ROW),
        },
        max_move_mm=20.0,
        workspace_mm=((-30.0, 30.0), (-90.0, 90.0)),
        work_frame="alphabet",
        grid_spacing_mm=3.0,
        grid_depth_step_mm=1.0,
        typing_sequences=10,
        types_sentences=True,
    ),
}
"""The key sets, by name."""


@dataclass(frozen=True)
class RegisteredTask:
    """One registered environment id.

    Attributes:
        env_id: the Gymnasium id.
        keys: its key set (a name in :data:`KEY_SETS`).
        continuous: continuous (dx, dy, depth) actions instead of grid moves.
        label: the reports' short name (the paper's Table III rows: ``"disc arrow"``...).
        budget_steps: the official training budget in environment steps: the leaderboard ranks
            methods trained within it together (more is listed apart). None: no budget is set.
        max_episode_steps: the registry's time limit.
    """

    env_id: str
    keys: str
    continuous: bool
    label: str
    budget_steps: int | None = None
    max_episode_steps: int = MAX_EPISODE_STEPS

    @property
    def name(self) -> str:
        """The id without its namespace (``DiscreteArrows-v0``): run folders and reports name tasks so."""
        return self.env_id.partition("/")[2]

    @property
    def entry_point(self) -> str:
        """The environment class of the action kind, by its import path (nothing is imported)."""
        kind = "Continuous" if self.continuous else "Discrete"
        return f"tactile_braille.envs.{kind.lower()}:{kind}BrailleEnv"

    @property
    def vector_entry_point(self) -> str:
        """The batched environment class of the action kind, by its import path."""
        kind = "Continuous" if self.continuous else "Discrete"
        return f"tactile_braille.envs.vector:Vector{kind}BrailleEnv"


REGISTERED_TASKS: tuple[RegisteredTask, ...] = (
    RegisteredTask("tactile_braille/DiscreteArrows-v0", "arrows", False, "disc arrow", 6_250),
    RegisteredTask("tactile_braille/DiscreteAlphabet-v0", "alphabet", False, "disc alpha", 25_000),
    RegisteredTask("tactile_braille/ContinuousArrows-v0", "arrows", True, "cont arrow", 25_000),
    RegisteredTask("tactile_braille/ContinuousAlphabet-v0", "alphabet", True, "cont alpha", 25_000),
)
"""The registered tasks, in the paper's order (reports list them so). Their budgets are the paper's
Table III runs, 25, 100 and 100 epochs of 250 steps, and for the continuous alphabet (which the
paper trained for 872 epochs and more) the 100 epochs our runs of the paper's agents had (0.6-1.0
hours each on one CPU thread with bf16)."""

ENV_IDS: tuple[str, ...] = tuple(task.env_id for task in REGISTERED_TASKS)


def registered_task(task: str) -> RegisteredTask | None:
    """The registered task ``task`` (its id, with or without its namespace); None for a task registered
    elsewhere."""
    return next((t for t in REGISTERED_TASKS if task in (t.name, t.env_id)), None)


def official_budget(task: str) -> int | None:
    """The official training budget, in environment steps, of the registered task ``task`` (its id,
    with or without its namespace); None for a task registered elsewhere or without one."""
    registered = registered_task(task)
    return None if registered is None else registered.budget_steps
