"""The examples/ scripts run as users run them (tiny budgets here; the leaderboard's are in their notes)."""

from __future__ import annotations

import importlib.util
from pathlib import Path

import pytest

from tactile_braille.evaluation.results import read_result

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"


def _load(name: str):
    spec = importlib.util.spec_from_file_location(name, EXAMPLES / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.mark.parametrize(("task", "algo"), [("DiscreteArrows-v0", "dqn"), ("ContinuousArrows-v0", "sac")])
def test_sb3_her_trains_scores_and_writes_a_results_file(env_datasets, tmp_path, task, algo):
    pytest.importorskip("stable_baselines3")
    output = tmp_path / f"{task}__{algo}.json"
    argv = [task, algo, "--steps", "50", "--learning-starts", "30", "--seed", "3", "--output", str(output),
            "--dataset", str(env_datasets[f"tactile_braille/{task}"])]  # fmt: skip
    assert _load("sb3_her").main(argv) == 0
    result = read_result(output)
    assert result["method"] == f"SB3 {algo.upper()} + HER" and result["track"] == "tactile"
    assert result["seed"] == 3 and result["budget"]["env_steps"] == 50
    assert result["report"]["keys_asked"] == 96 and 0.0 <= result["report"]["accuracy"] <= 1.0
    with pytest.raises(SystemExit):  # an existing results file is never overwritten
        _load("sb3_her").main(argv)
