"""The tasks as data (tactile_braille/_tasks.py): each registered id comes from its row, and every layer
reads the key sets' rows rather than asking which key set a task types."""

from __future__ import annotations

import dataclasses

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.envs.registration import load_env_creator

from tactile_braille._tasks import ENV_IDS, KEY_SETS, REGISTERED_TASKS, KeySet
from tactile_braille.envs.core import cell_positions_mm
from tactile_braille.envs.registry import task_name, task_of
from tactile_braille.envs.tasks import Task
from tactile_braille.envs.world import GRIDS
from tactile_braille.keyboard.calibration import CALIBRATED_FRAMES
from tactile_braille.keyboard.layout import NONE_KEY, KeyboardLayout, key_set


@pytest.mark.parametrize("row", REGISTERED_TASKS, ids=lambda row: row.name)
def test_each_id_is_registered_from_its_row(row):
    spec = gym.spec(row.env_id)
    assert spec.kwargs == {"keys": row.keys}
    assert spec.max_episode_steps == row.max_episode_steps
    assert load_env_creator(spec.entry_point).continuous == row.continuous
    assert load_env_creator(spec.vector_entry_point).continuous == row.continuous
    assert task_of(row.env_id) == Task(row.keys, row.continuous)
    assert task_name(row.env_id) == row.name
    assert row.keys in KEY_SETS


@pytest.mark.parametrize("row", KEY_SETS.values(), ids=lambda row: row.name)
def test_each_key_set_row_is_whole(row):
    assert KEY_SETS[row.name] is row
    assert key_set(row.name) == row.keys  # the keyboard's key sets are the rows'
    assert set(row.key_grids) == set(GRIDS)  # a grid for each name the environments take
    for grid in row.key_grids.values():
        assert len({len(cells) for cells in grid}) == 1, "rectangular"
        cells = {cell for cells in grid for cell in cells}
        assert cells - {NONE_KEY} == set(row.keys)  # every key once at least; off the keys is NONE
    (x_low, x_high), (y_low, y_high) = row.workspace_mm
    assert x_low < x_high and y_low < y_high and row.max_move_mm > 0
    assert row.work_frame in CALIBRATED_FRAMES
    assert row.grid_spacing_mm > 0 and row.grid_depth_step_mm > 0
    assert row.typing_sequences is None or row.typing_sequences > 0


def test_the_presets_and_the_reports_have_a_row_per_registered_task():
    from tactile_braille.agents.presets import TASK_PRESETS
    from tactile_braille.evaluation.report import TASK_NAMES

    assert tuple(TASK_PRESETS) == ENV_IDS
    assert list(TASK_NAMES) == [row.name for row in REGISTERED_TASKS]


def test_a_new_key_set_is_a_row_every_layer_reads(monkeypatch):
    """A toy key set (three letters in a row) added to the table: the task, its grid's cells, the typing
    sequences and the stored grid follow from its row alone."""
    from tactile_braille.datasets.procedures import GridTaps
    from tactile_braille.evaluation.protocol import paper_sequences

    toy = KeySet(
        name="qwe", keys=("Q", "W", "E"), key_grids={"rig": (tuple("QWE"),), "released": (tuple("QWE"),)},
        max_move_mm=5.0, workspace_mm=((-1.0, 1.0), (-2.0, 2.0)), work_frame="alphabet",
        grid_spacing_mm=1.0, grid_depth_step_mm=2.0, typing_sequences=None, types_sentences=False,
    )  # fmt: skip
    monkeypatch.setitem(KEY_SETS, "qwe", toy)
    task = Task("qwe", continuous=True)
    assert (task.goal_keys, task.max_move_mm, task.workspace_mm) == (toy.keys, 5.0, toy.workspace_mm)
    assert task.frame_origin_mm == Task("alphabet", continuous=True).frame_origin_mm
    layout = KeyboardLayout()
    np.testing.assert_array_equal(
        cell_positions_mm(Task("qwe", continuous=False), layout)[0], [layout.centre_mm(k) for k in "QWE"]
    )
    assert len(paper_sequences("qwe")) == 6
    grid = GridTaps(keys="qwe")
    assert (grid.x_range_mm, grid.y_range_mm, grid.depth_step_mm) == ((-1.0, 1.0), (-2.0, 2.0), 2.0)


@pytest.mark.parametrize("keys", KEY_SETS)
def test_each_grid_cell_of_a_key_lies_on_that_key(keys):
    layout = KeyboardLayout()
    for grid_name in GRIDS:
        task = Task(keys, continuous=False, grid=grid_name)
        positions = cell_positions_mm(task, layout)
        for (r, c), name in np.ndenumerate(task.key_grid):
            if name == NONE_KEY:
                continue
            key = layout.key(name)
            x, y = positions[r, c]
            half_width_mm = key.width_u * layout.pitch_mm / 2
            assert x == key.centre_x_mm and abs(y - key.centre_y_mm) < half_width_mm, (grid_name, name)
            if key.width_u == 1:
                assert y == key.centre_y_mm, (grid_name, name)  # a key of one cell: its very centre


def test_a_task_of_your_own_is_registered_from_rows_and_plays():
    """register_task: a new key set's id made with Gymnasium on the live renderer, a press of its goal
    rewarded; the settings know it; a clash is refused before anything is registered."""
    import tactile_braille
    from tactile_braille.agents.config import TrainConfig

    qwe = tactile_braille.KeySet(
        name="qwe_own", keys=("Q", "W", "E"), key_grids={"rig": (tuple("QWE"),), "released": (tuple("QWE"),)},
        max_move_mm=10.0, workspace_mm=((-10.0, 10.0), (-25.0, 25.0)), work_frame="alphabet",
        grid_spacing_mm=1.0, grid_depth_step_mm=1.0, typing_sequences=None, types_sentences=False,
    )  # fmt: skip
    task = tactile_braille.RegisteredTask("mylab/DiscreteQWE-v0", "qwe_own", continuous=False, label="qwe")
    try:
        tactile_braille.register_task(task, qwe)
        env = gym.make(task.env_id, backend="render")
        observation, info = env.reset(seed=0)
        assert observation["desired_goal"].shape == (3,) and info["goal_key"] in "QWE"
        column = "QWE".index(info["goal_key"])
        start = "QWE".index(
            min("QWE", key=lambda k: abs(info["sensor_pose_mm"][1] - env.unwrapped.layout.centre_mm(k)[1]))
        )
        moves = [3 if column > start else 2] * abs(column - start)  # RIGHT or LEFT along the row
        for action in [*moves, 4]:
            observation, reward, terminated, _, info = env.step(action)
        assert terminated and reward == 1.0 and info["pressed_key"] == info["goal_key"]
        assert TrainConfig(task=task.env_id, backend="render").braille_task.keys == "qwe_own"
        with pytest.raises(ValueError, match="registered already"):
            tactile_braille.register_task(task, qwe)
        other = tactile_braille.RegisteredTask(
            "mylab/ContinuousQWE-v0", "qwe_own", continuous=True, label="q"
        )
        with pytest.raises(ValueError, match="exists with other contents"):
            tactile_braille.register_task(other, dataclasses.replace(qwe, max_move_mm=5.0))
        assert "mylab/ContinuousQWE-v0" not in gym.registry
        with pytest.raises(ValueError, match="unknown key set 'zxc'"):
            tactile_braille.register_task(tactile_braille.RegisteredTask("mylab/Z-v0", "zxc", False, "z"))
    finally:
        KEY_SETS.pop("qwe_own", None)
        for env_id in ("mylab/DiscreteQWE-v0", "mylab/ContinuousQWE-v0"):
            gym.registry.pop(env_id, None)
