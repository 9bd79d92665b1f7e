"""tools/offline_gpu_sweep.sh: bad input refused before it installs or runs anything, and its `run` path.

`prepare` downloads the wheels an offline GPU node lacks (network), and `start`/`collect` span two
jobs on the node, so those are run by hand (docs/evaluation.md). The `run` path (install the carried wheels,
sweep for a budget, archive, pack) runs end to end on the CPU in a slow test, with a placeholder wheel.
"""

from __future__ import annotations

import base64
import hashlib
import json
import os
import subprocess
import sys
import tarfile
import zipfile
from pathlib import Path

import pytest

SCRIPT = Path(__file__).resolve().parents[1] / "tools" / "offline_gpu_sweep.sh"


def offline_gpu_sweep(*args: str, **env: str) -> subprocess.CompletedProcess:
    environment = {key: value for key, value in os.environ.items() if key != "OUT"} | env
    return subprocess.run(
        ["bash", str(SCRIPT), *args], capture_output=True, text=True, env=environment, timeout=60
    )


@pytest.mark.parametrize(
    ("args", "env", "message"),
    [
        ((), {}, "tools/offline_gpu_sweep.sh prepare"),  # no verb: the usage
        (("run", "500"), {}, "tools/offline_gpu_sweep.sh run BUDGET_S"),  # too few arguments: the usage
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
        (
            ("tune", "500", "500", "DiscreteArrows-v0", "dqn"),
            {"OUT": "/tmp"},
            "offline_gpu_sweep.sh tune SEARCH_S",
        ),
        (
            ("tune", "ten", "500", "DiscreteArrows-v0", "dqn", "4"),
            {"OUT": "/tmp"},
            "SEARCH_S must be whole seconds",
        ),
        (
            ("tune", "500", "500", "DiscreteArrows-v0", "dqn", "0"),
            {"OUT": "/tmp"},
            "TRIALS must be a whole number",
        ),
        (("tune", "500", "500", "DiscreteArrows-v0", "dqn", "4"), {}, "OUT is not set"),
        (
            ("tune", "500", "0", "DiscreteArrows-v0", "dqn", "4"),
            {"OUT": "/tmp"},
            "FINAL_S must be more than 0 seconds",
        ),
        (("collect",), {"OUT": "/tmp"}, "tools/offline_gpu_sweep.sh collect WAIT_S"),
        (("collect", "soon"), {"OUT": "/tmp"}, "WAIT_S must be whole seconds, got 'soon'"),
        (("collect", "10"), {"STATE": "/nonexistent/state"}, "OUT is not set"),
        (
            ("collect", "10"),
            {"OUT": "/tmp", "STATE": "/nonexistent/state"},
            "no sweep was started in /nonexistent/state: run 'start' first",
        ),
    ],
)
def test_offline_gpu_sweep_refuses_bad_input_with_a_clear_message(args, env, message, tmp_path):
    before = sorted(SCRIPT.parent.parent.glob("results/x"))
    result = offline_gpu_sweep(*args, **env)
    assert result.returncode == 2
    assert message in result.stderr
    assert sorted(SCRIPT.parent.parent.glob("results/x")) == before  # nothing was made


def test_offline_gpu_sweep_asks_for_the_carried_wheels(tmp_path):
    copy = tmp_path / "repo"
    (copy / "tools").mkdir(parents=True)
    (copy / "tools" / SCRIPT.name).write_text(SCRIPT.read_text())
    result = subprocess.run(
        ["bash", str(copy / "tools" / SCRIPT.name), "run", "500", "results/x", "--paper"],
        capture_output=True, text=True, env={**os.environ, "OUT": str(tmp_path)}, timeout=60,
    )  # fmt: skip
    assert result.returncode == 2
    assert "no wheels in .whl/: run 'prepare' on a machine with network and carry .whl" in result.stderr
    assert not (copy / "results").exists()


def _placeholder_wheel(folder: Path) -> Path:
    """A minimal valid pure-Python wheel: the script installs whatever is carried in .whl/."""
    name, version = "offline_gpu_placeholder", "0.1"
    files = {
        f"{name}/__init__.py": "",
        f"{name}-{version}.dist-info/METADATA": f"Metadata-Version: 2.1\nName: {name}\nVersion: {version}\n",
        f"{name}-{version}.dist-info/WHEEL": (
            "Wheel-Version: 1.0\nGenerator: tests\nRoot-Is-Purelib: true\nTag: py3-none-any\n"
        ),
    }
    info = f"{name}-{version}.dist-info"

    def digest(text: str) -> str:
        return base64.urlsafe_b64encode(hashlib.sha256(text.encode()).digest()).rstrip(b"=").decode()

    record = [f"{path},sha256={digest(text)},{len(text.encode())}" for path, text in files.items()]
    files[f"{info}/RECORD"] = "\n".join([*record, f"{info}/RECORD,,"]) + "\n"
    folder.mkdir(parents=True)
    wheel = folder / f"{name}-{version}-py3-none-any.whl"
    with zipfile.ZipFile(wheel, "w") as archive:
        for path, text in files.items():
            archive.writestr(path, text)
    return wheel


def _node_checkout(tmp_path: Path) -> tuple[Path, Path]:
    """A checkout as a node gets it (the script, a carried wheel, a .data folder), and an empty $OUT."""
    copy = tmp_path / "repo"
    (copy / "tools").mkdir(parents=True)
    (copy / "tools" / SCRIPT.name).write_text(SCRIPT.read_text())
    _placeholder_wheel(copy / ".whl")
    (copy / ".data").mkdir()
    out = tmp_path / "out"
    out.mkdir()
    return copy, out


@pytest.mark.slow
def test_offline_gpu_sweep_runs_a_variant_through_sweep_and_packs_its_record(env_datasets, tmp_path):
    """SWEEP_COMMAND=sweep end to end on the CPU: install, a variant's trial, archive, records.tgz.

    The GPU node's only differences are DEVICE and the wheels carried (here a placeholder, as
    gymnasium is already installed); about 20 s, so `make test-slow`.
    """
    copy, out = _node_checkout(tmp_path)
    dataset = env_datasets["tactile_braille/DiscreteArrows-v0"]
    result = subprocess.run(
        ["bash", str(copy / "tools" / SCRIPT.name), "run", "300", "results/x",
         "--tasks", "DiscreteArrows-v0", "--algos", "dqn", "--seeds", "3", "--root", "runs/s",
         "--epochs", "1", "--steps-per-epoch", "30", "--start-steps", "20", "--updates-per-step", "1",
         "--evaluation.test-episodes", "1", "--replay.capacity", "500", "--agent.batch-size", "8",
         "--agent.hidden", "16", "--dataset", str(dataset), "--variant", "tiny"],
        capture_output=True, text=True, timeout=300,
        env={**os.environ, "OUT": str(out), "SWEEP_COMMAND": "sweep", "DEVICE": "cpu", "JOBS": "1",
             "PYTHON": sys.executable, "SITE": str(tmp_path / "site")},
    )  # fmt: skip
    assert result.returncode == 0, result.stderr
    assert (tmp_path / "site" / "offline_gpu_placeholder").is_dir()  # the carried wheel was installed
    trial = "DiscreteArrows-v0__dqn__tiny__3"
    [row] = [line.split("\t") for line in (out / "epochs.tsv").read_text().splitlines()[1:]]
    assert row[0] == f"runs/s/{trial}" and row[1] == "1"
    with tarfile.open(out / "records.tgz") as packed:
        names = set(packed.getnames())
        log = packed.extractfile("sweep.log").read().decode()
    assert {f"results/x/{trial}/typing.json", f"results/x/{trial}/progress.csv"} <= names
    assert "sweep exit status 0" in log


def _tune(copy: Path, out: Path, *args: str, **env: str) -> None:
    """The node's copy of the script's `tune ARGS` on the CPU (its wheels installed under the checkout's
    parent), with ENV beside the node's own; it must succeed."""
    result = subprocess.run(
        ["bash", str(copy / "tools" / SCRIPT.name), "tune", *args],
        capture_output=True, text=True, timeout=600,
        env={**os.environ, "OUT": str(out), "DEVICE": "cpu", "PYTHON": sys.executable,
             "SITE": str(copy.parent / "site"), **env},
    )  # fmt: skip
    assert result.returncode == 0, result.stderr


@pytest.mark.slow
def test_offline_gpu_sweep_tunes_with_workers_sharing_one_study_and_packs_the_search(env_datasets, tmp_path):
    """The `tune` verb end to end on the CPU: two processes share the SQLite study and stop at its
    trials (two, not one each more), then the final run of a fresh seed; all of it in tuning.tgz."""
    copy, out = _node_checkout(tmp_path)
    dataset = env_datasets["tactile_braille/DiscreteArrows-v0"]
    _tune(copy, out, "240", "240", "DiscreteArrows-v0", "dqn", "2", "--dataset", str(dataset),
          JOBS="2", STEPS="60", SEEDS="5", FINAL_STEPS="80")  # fmt: skip
    with tarfile.open(out / "tuning.tgz") as packed:
        names = set(packed.getnames())
        summary = json.loads(packed.extractfile("runs/tune/DiscreteArrows-v0__dqn.json").read())
        final = json.loads(
            packed.extractfile("results/leaderboard/sb3-tuned/DiscreteArrows-v0__dqn__5.json").read()
        )
    assert {
        "runs/tune/DiscreteArrows-v0__dqn.db",
        "./search_0.log",
        "./search_1.log",
        "./final_5.log",
    } <= names
    assert summary["trials"] == 2 and len(summary["trial_log"]) == 2 and summary["steps"] == 60
    assert final["seed"] == 5 and final["tuning"]["trials"] == 2 and final["budget"]["env_steps"] == 80

    # SEARCH_S 0: no search, a further seed from the search's record alone (as committed in results/searches)
    record = copy / "record"
    record.mkdir()
    (record / "DiscreteArrows-v0__dqn.json").write_text(json.dumps(summary))
    again = tmp_path / "again"
    again.mkdir()
    _tune(copy, again, "0", "240", "DiscreteArrows-v0", "dqn", "2", "--dataset", str(dataset),
          STUDY="record", SEEDS="6", FINAL_STEPS="80")  # fmt: skip
    assert not list(record.glob("*.db"))  # no new study beside the record
    with tarfile.open(again / "tuning.tgz") as packed:
        names = set(packed.getnames())
        sixth = json.loads(
            packed.extractfile("results/leaderboard/sb3-tuned/DiscreteArrows-v0__dqn__6.json").read()
        )
    assert "./final_6.log" in names and not any(name.startswith("./search_") for name in names)
    assert sixth["tuning"]["best"] == summary["best"] and sixth["budget"]["env_steps"] == 80


@pytest.mark.slow
def test_offline_gpu_sweep_tunes_one_of_our_agents_from_a_preset(env_datasets, tmp_path):
    """`tune` with PRESET: `tactile-braille tune search|run` from the preset, two processes sharing the
    study, then a fresh seed's run whose record carries the search; all of it in tuning.tgz."""
    copy, out = _node_checkout(tmp_path)
    dataset = env_datasets["tactile_braille/DiscreteArrows-v0"]
    _tune(copy, out, "300", "300", "DiscreteArrows-v0", "planner", "2", "--dataset", str(dataset),
          JOBS="2", PRESET="fast-tactile", EPOCHS="1", FINAL_EPOCHS="1", SEEDS="5")  # fmt: skip
    name = "DiscreteArrows-v0__planner__fast-tactile"
    with tarfile.open(out / "tuning.tgz") as packed:
        names = set(packed.getnames())
        summary = json.loads(packed.extractfile(f"runs/tune/{name}.json").read())
        final = json.loads(
            packed.extractfile("results/tuned/DiscreteArrows-v0__planner__tuned__5/result.json").read()
        )
    assert {f"runs/tune/{name}.db", "./search_0.log", "./search_1.log", "./final_5.log"} <= names
    assert summary["trials"] == 2 and summary["preset"] == "fast-tactile" and summary["steps"] == 250
    assert final["seed"] == 5 and final["tuning"]["best"] == summary["best"]
    assert final["budget"]["env_steps"] == 250 and final["method"].startswith("tactile_braille planner")
