"""tools/lent_gpu_sweep.sh refuses bad input before it installs or runs anything.

Its whole path (install the carried wheels, sweep for a budget, archive, pack; or start, then collect)
needs the wheels that ``prepare`` downloads, so it is run by hand (docs/evaluation.md); these are its
checks.
"""

from __future__ import annotations

import os
import subprocess
from pathlib import Path

import pytest

SCRIPT = Path(__file__).resolve().parents[1] / "tools" / "lent_gpu_sweep.sh"


def lent_gpu_sweep(*args: str, **env: str) -> subprocess.CompletedProcess:
    environment = {key: value for key, value in os.environ.items() if key != "OUT"} | env
    return subprocess.run(
        ["bash", str(SCRIPT), *args], capture_output=True, text=True, env=environment, timeout=60
    )


@pytest.mark.parametrize(
    ("args", "env", "message"),
    [
        ((), {}, "tools/lent_gpu_sweep.sh prepare"),  # no verb: the usage
        (("run", "500"), {}, "tools/lent_gpu_sweep.sh run BUDGET_S"),  # too few arguments: the usage
        (
            ("run", "ten", "results/x", "--paper"),
            {"OUT": "/tmp"},
            "BUDGET_S must be whole seconds, got 'ten'",
        ),
        (("run", "500", "results/x", "--paper"), {}, "OUT is not set"),
        (
            ("start", "500", "results/x", "--paper"),
            {"SWEEP_COMMAND": "train"},
            "SWEEP_COMMAND must be benchmark or sweep, got 'train'",
        ),
        (("start", "ten", "results/x", "--paper"), {}, "BUDGET_S must be whole seconds, got 'ten'"),
        (("collect",), {"OUT": "/tmp"}, "tools/lent_gpu_sweep.sh collect WAIT_S"),
        (("collect", "soon"), {"OUT": "/tmp"}, "WAIT_S must be whole seconds, got 'soon'"),
        (("collect", "10"), {"STATE": "/nonexistent/state"}, "OUT is not set"),
        (
            ("collect", "10"),
            {"OUT": "/tmp", "STATE": "/nonexistent/state"},
            "no sweep was started in /nonexistent/state: run 'start' first",
        ),
    ],
)
def test_lent_gpu_sweep_refuses_bad_input_with_a_clear_message(args, env, message, tmp_path):
    before = sorted(SCRIPT.parent.parent.glob("results/x"))
    result = lent_gpu_sweep(*args, **env)
    assert result.returncode == 2
    assert message in result.stderr
    assert sorted(SCRIPT.parent.parent.glob("results/x")) == before  # nothing was made


def test_lent_gpu_sweep_asks_for_the_carried_wheels(tmp_path):
    copy = tmp_path / "repo"
    (copy / "tools").mkdir(parents=True)
    (copy / "tools" / SCRIPT.name).write_text(SCRIPT.read_text())
    result = subprocess.run(
        ["bash", str(copy / "tools" / SCRIPT.name), "run", "500", "results/x", "--paper"],
        capture_output=True, text=True, env={**os.environ, "OUT": str(tmp_path)}, timeout=60,
    )  # fmt: skip
    assert result.returncode == 2
    assert "no wheels in .whl/: run 'prepare' here and carry .whl" in result.stderr
    assert not (copy / "results").exists()
