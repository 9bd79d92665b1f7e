"""Warm starts (``train --init-from RUN_DIR``): a new run in another world, from another run's agent.

The paper's Discussion reports that policies trained on a 6 mm grid sped up learning on the 3 mm
grid; these tests pin down what a warm start takes (the agent, whole), what it leaves (replay,
counters, generators), what it refuses, and that a resume does not start it again.
"""

from __future__ import annotations

import json
from pathlib import Path

import pytest
import torch

from agents_helpers import CONTINUOUS_TASK, touch_config
from tactile_braille.agents import SACConfig
from tactile_braille.agents.config import replace_settings
from tactile_braille.agents.run import CHECKPOINT_FILE, INIT_FILE, read_config
from tactile_braille.agents.training import train
from tactile_braille.cli import main
from tactile_braille.datasets.procedures import GridTaps
from tactile_braille.rigs.virtual import VirtualRig

COARSE = GridTaps(keys="arrows", spacing_mm=10, depth_step_mm=3)
"""3 x 5 x 3 taps: a coarser grid than the source run's, as the paper's 6 mm grid is."""


@pytest.fixture(scope="module")
def source(env_datasets, tmp_path_factory) -> Path:
    """A finished one-epoch SAC run with a fitted touch encoder (updates and a fit have run)."""
    folder = tmp_path_factory.mktemp("warm") / "source"
    return train(touch_config(env_datasets, "sac"), run_dir=folder, progress=False)


@pytest.fixture(scope="module")
def coarse_grid(tmp_path_factory) -> Path:
    from tactile_braille.datasets.collector import collect

    path = tmp_path_factory.mktemp("coarse") / "grid-arrows-10mm.h5"
    collect(VirtualRig(seed=0), COARSE, path, seed=0, progress=False)
    return path


def agent_state(run: Path) -> dict:
    return torch.load(run / CHECKPOINT_FILE, weights_only=False)["agent"]


def equal_states(a, b) -> bool:
    """Nested state dicts (networks, optimisers, temperature) equal value for value."""
    if isinstance(a, dict):
        return isinstance(b, dict) and a.keys() == b.keys() and all(equal_states(a[k], b[k]) for k in a)
    if isinstance(a, list | tuple):
        return len(a) == len(b) and all(equal_states(x, y) for x, y in zip(a, b, strict=True))
    if isinstance(a, torch.Tensor):
        return torch.equal(a, b)
    return a == b


def test_a_warm_start_in_another_world_begins_with_the_source_agent_whole(
    source, coarse_grid, env_datasets, tmp_path
):
    # No update and no encoder fit happen before the start steps end: the run ends as it began.
    warm = touch_config(
        env_datasets, "sac", seed=1, steps_per_epoch=10, start_steps=20, dataset=str(coarse_grid),
        init_from=str(source),
    )  # fmt: skip
    run = train(warm, run_dir=tmp_path / "warm", progress=False)
    assert equal_states(agent_state(run), agent_state(source))
    # A cold start with the same settings begins elsewhere (the check above can fail).
    cold = train(replace_settings(warm, {"init_from": None}), run_dir=tmp_path / "cold", progress=False)
    assert not equal_states(agent_state(cold), agent_state(source))
    record = json.loads((run / INIT_FILE).read_text())
    assert record["run"] == str(source) and record["seed"] == 0 and record["epochs"] == 1
    assert record["env_steps"] == 20 and record["updates"] > 0 and len(record["test_returns"]) == 1
    assert record["world"]["procedure"]["spacing_mm"] == 4  # the source's world, not the run's
    assert json.loads((run / "world.json").read_text())["procedure"]["spacing_mm"] == 10
    assert read_config(run).init_from == str(source)


def test_a_resumed_warm_start_continues_its_own_checkpoint(source, env_datasets, tmp_path):
    copy = tmp_path / "source"
    copy.mkdir()
    for path in source.iterdir():
        if path.is_file():
            (copy / path.name).write_bytes(path.read_bytes())
    run = train(touch_config(env_datasets, "sac", seed=2, init_from=str(copy)), run_dir=tmp_path / "warm",
                progress=False)  # fmt: skip
    recorded = (run / INIT_FILE).read_text()
    (copy / CHECKPOINT_FILE).unlink()  # a resume that went back to the source would fail now
    assert main(["train", "--resume", str(run), "--epochs", "2", "--quiet"]) == 0
    assert (run / INIT_FILE).read_text() == recorded
    assert torch.load(run / CHECKPOINT_FILE, weights_only=False)["epoch"] == 1


@pytest.mark.parametrize(
    ("changes", "message"),
    [
        ({"agent": SACConfig(hidden=(16,), batch_size=8, learning_rate=0.01)},
         r"other settings \(agent.learning_rate: 0.0005 -> 0.01\)"),
        ({"touch": {"inputs": "readout"}}, r"other settings \(touch.inputs: 'features' -> 'readout'\)"),
        ({"task": "tactile_braille/ContinuousAlphabet-v0"}, r"task: 'tactile_braille/ContinuousArrows-v0' "),
    ],
)  # fmt: skip
def test_a_warm_start_from_another_learner_is_refused_before_its_folder_is_made(
    source, env_datasets, tmp_path, changes, message
):
    config = touch_config(env_datasets, "sac", init_from=str(source), **changes)
    with pytest.raises(ValueError, match=message):
        train(config, run_dir=tmp_path / "warm", progress=False)
    assert not (tmp_path / "warm").exists()


def test_the_command_line_refuses_a_bad_warm_start_in_one_line(tmp_path, capsys):
    run = tmp_path / "warm"
    assert main(["train", CONTINUOUS_TASK, "sac", "--init-from", str(tmp_path / "nowhere"),
                 "--run-dir", str(run), "--quiet"]) != 0  # fmt: skip
    error = capsys.readouterr().err
    assert error.count("\n") == 1 and "no training run there" in error and not run.exists()


def test_a_warm_start_without_a_readable_source_or_from_itself_is_refused(source, env_datasets, tmp_path):
    bare, damaged = tmp_path / "bare", tmp_path / "damaged"
    for folder in (bare, damaged):
        folder.mkdir()
        (folder / "config.json").write_text((source / "config.json").read_text())
    (damaged / CHECKPOINT_FILE).write_bytes((source / CHECKPOINT_FILE).read_bytes()[:1000])  # truncated
    before = {path.name: path.read_bytes() for path in source.iterdir() if path.is_file()}
    for origin, message in [
        (tmp_path / "nowhere", "no training run there"),
        (bare, "has no checkpoint.pt"),
        (damaged, "checkpoint.pt is unreadable"),
        (source, "this run's own folder"),
    ]:
        run = source if origin == source else tmp_path / "warm"
        with pytest.raises(ValueError, match=message):
            train(touch_config(env_datasets, "sac", init_from=str(origin)), run_dir=run, progress=False)
        assert not (tmp_path / "warm").exists()
    assert {path.name: path.read_bytes() for path in source.iterdir() if path.is_file()} == before
