"""Every maintained script of benchmarks/ runs to its end and prints its figures, at tiny sizes.

The figures themselves are the scripts' business (they print ratios side by side, and a shared machine
makes absolute times noisy); here each is only run, as a user runs it, so that none rots. Slow: a few
minutes in all (`make test-slow`). Scripts that read training runs are in studies/ (tests/test_studies.py).
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]

TINY = {
    "adam_epsilon.py": ["--updates", "2"],
    "activation_map.py": [],
    "all_goals_cost.py": ["--updates", "2", "--rounds", "1"],
    "classifier_robustness.py": ["--epochs", "1", "--per-key", "2"],
    "collect.py": ["--per-key", "2", "--reads", "1"],
    "env_throughput.py": ["--seconds", "0.2", "--num-envs", "2"],
    "policies.py": ["--episodes", "2"],
    "precision_cost.py": ["--updates", "2", "--rounds", "1"],
    "render.py": ["--taps", "4"],
    "sensor_sensitivity.py": ["--pairs", "0.6,2.5", "--epochs", "1"],
    "separability.py": ["--train", "2", "--val", "1"],
    "tap_identifiability.py": ["--resets", "20"],
    "train_throughput.py": ["--start", "20", "--steps", "20", "--updates", "2", "--algos", "dqn"],
    "typing_bounds.py": ["--seeds", "1"],
    "typing_protocols.py": ["--seeds", "1"],
}
"""Each maintained script and the arguments that make it quick."""


def test_every_script_of_benchmarks_is_listed():
    assert sorted(TINY) == sorted(path.name for path in (ROOT / "benchmarks").glob("*.py"))


@pytest.mark.slow
@pytest.mark.parametrize("script", sorted(TINY))
def test_the_script_runs_and_prints_its_figures(script, tmp_path):
    finished = subprocess.run(
        [sys.executable, str(ROOT / "benchmarks" / script), *TINY[script]],
        cwd=tmp_path,  # a script's default outputs land here, not in the checkout
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert finished.returncode == 0, finished.stderr[-2000:]
    assert len(finished.stdout.splitlines()) >= 2, finished.stdout
