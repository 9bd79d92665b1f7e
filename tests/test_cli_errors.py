"""Every error a user can cause ends in one line and exit status 2, before anything is written.

A table of the inputs a review found ending in tracebacks or in folders that then blocked a re-run,
each run through ``tactile_braille.cli.main`` as the shell runs it.
"""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest
import torch

from tactile_braille.agents import TrainConfig, train
from tactile_braille.cli import main

RECORD = str(Path(__file__).parents[1] / "results" / "tuning" / "DA_relabel-all_utd4_100")  # committed
RESULTS = Path(__file__).parents[1] / "results" / "leaderboard"  # committed
RESULT = str(RESULTS / "cleanrl" / "DiscreteArrows-v0__dqn_her__0.json")
ELSEWHERE = str(RESULTS / "sb3" / ".." / "cleanrl" / "DiscreteArrows-v0__dqn_her__0.json")  # the same file
ARROWS = "tactile_braille/DiscreteArrows-v0"
RUNS = ("trained", "truncated", "torn", "no-config", "planner")
"""The runs the ``runs`` fixture makes (its docstring says what each is)."""

CASES = {
    "train --seed -1": (["train", "DiscreteArrows-v0", "--seed", "-1", "--run-dir", "{tmp}/run"],
                        "TrainConfig.seed must be at least 0"),
    "train --device bogus": (["train", "DiscreteArrows-v0", "--device", "bogus", "--run-dir", "{tmp}/run"],
                             "device must be cpu, cuda, cuda:N or mps"),
    "train --epochs 1e30": (["train", "DiscreteArrows-v0", "--epochs", "1e30", "--run-dir", "{tmp}/run"],
                            "invalid int value: '1e30'"),
    "collect --seed -1": (["collect", "--seed", "-1", "--output", "{tmp}/c.h5"], "must be a non-negative"),
    "collect --yaw-range-deg -5": (["collect", "--yaw-range-deg", "-5", "--output", "{tmp}/c.h5"],
                                   "yaw_range_deg must be a bound >= 0, got -5.0"),
    "data --seed -1": (["data", "--seed", "-1"], "must be a non-negative integer, got -1"),
    "classify --threads 0": (["classify", "--threads", "0"], "must be a positive integer, got 0"),
    "classify into an existing folder": (["classify", "--output", "{tmp}"], "exists; choose another folder"),
    "classify into a file": (["classify", "--output", "{tmp}/file"], "(it is a file)"),
    "report --episodes -1": (["report", "{tmp}/run", "--episodes", "-1"], "must be a positive integer"),
    "report a record without --output": (["report", RECORD], "table records with --output"),
    "rig check --keys ZZ": (["rig", "check", "--keys", "ZZ"], "--keys: unknown keys ['ZZ']"),
    "rig check, settings {}": (["rig", "check", "--config", "{tmp}/rig.json"],
                               "the UR5 rig settings lack ['host'"),
    "show --output a folder": (["show", "--output", "{tmp}"], "is a folder; name the file to write"),
    "rig crop --output a folder": (["rig", "crop", "--simulated", "--output", "{tmp}"], "is a folder"),
    "collect --output under a file": (["collect", "--keys", "arrows", "--output", "{tmp}/file/x.h5"],
                                      "Not a directory"),
    "evaluate a file": (["evaluate", "{tmp}/file"], "is not a training run (no config.json)"),
    "resume a folder with no run": (["train", "--resume", "{tmp}"], "is not a resumable run"),
    "resume a mistyped folder": (["train", "--resume", "{tmp}/typo"], "is not a resumable run"),
    "evaluate a run with --protocol": (["evaluate", "{tmp}", "--protocol", "released"],
                                       "--protocol is for --policy"),
    "evaluate a run with --epochs 0": (["evaluate", "{tmp}", "--epochs", "0"], "--epochs is for --policy"),
    "collect a grid of 0.001 mm": (["collect", "--procedure", "grid", "--keys", "arrows", "--spacing-mm",
                                    "0.001", "--output", "{tmp}/g.h5"], "taps, more than the 1,000,000"),
    "keycaps --resolution-mm 0.0001": (["keycaps", "--resolution-mm", "0.0001", "--out", "{tmp}/caps"],
                                       "finer than 0.01 mm"),
    "import a folder as its csv": (["import", "{tmp}", "--output", "{tmp}/i.h5"], "is not a file"),
    "leaderboard a results file twice": (["leaderboard", RESULT, RESULT], "are the same results file, given"),
    "leaderboard a file twice, spelt two ways": (["leaderboard", RESULT, ELSEWHERE],
                                                  "are the same results file, given"),
    # {tmp}/NAME, NAME in RUNS: a run the runs fixture (below) made, copied in.
    "evaluate a truncated checkpoint": (["evaluate", "{tmp}/truncated"], "checkpoint.pt is unreadable"),
    "evaluate --world, a truncated checkpoint": (["evaluate", "{tmp}/truncated", "--world", "render"],
                                                 "checkpoint.pt is unreadable"),
    "evaluate a run, then a truncated one": (["evaluate", "{tmp}/trained", "{tmp}/truncated"],
                                             "checkpoint.pt is unreadable"),
    "report a truncated checkpoint": (["report", "{tmp}/truncated"], "checkpoint.pt is unreadable"),
    "report a run, then a torn one": (["report", "{tmp}/trained", "{tmp}/torn", "--episodes", "1"],
                                      "its last row is torn"),
    "report a run, then one without config.json": (["report", "{tmp}/trained", "{tmp}/no-config"],
                                                    "no-config is not a training run (no config.json)"),
    "report --output, a run, then a torn one": (["report", "{tmp}/trained", "{tmp}/torn", "--output",
                                                 "{tmp}/out"], "its last row is torn"),
    "report --output, a run never evaluated": (["report", "{tmp}/trained", "--output", "{tmp}/out"],
                                               "has no typing evaluation of its last epoch: run `tactile"),
    "evaluate --env-steps abc": (["evaluate", "DiscreteArrows-v0", "--policy", "m:f", "--env-steps", "abc"],
                                 "argument --env-steps: invalid non-negative integer: 'abc'"),
    "report --episodes abc": (["report", "{tmp}/trained", "--episodes", "abc"],
                              "argument --episodes: invalid positive integer: 'abc'"),
    "classify --threads two": (["classify", "--threads", "two"], "invalid positive integer: 'two'"),
    "train --init-from a run of another algorithm": (
        ["train", "DiscreteArrows-v0", "dqn", "--init-from", "{tmp}/planner", "--run-dir", "{tmp}/warm"],
        "learnt with other settings (algo: 'planner' -> 'dqn'; "),
}  # fmt: skip
if not torch.cuda.is_available():
    CASES["train --device cuda without CUDA"] = (
        ["train", "DiscreteArrows-v0", "--device", "cuda", "--run-dir", "{tmp}/run"],
        "CUDA is not available",
    )


@pytest.fixture(scope="module")
def runs(env_datasets, tmp_path_factory) -> Path:
    """A folder of runs, as the cases name them: ``trained`` (a finished one-epoch DQN run, never
    evaluated), ``truncated`` (its checkpoint cut to 100 bytes), ``torn`` (the last row of its log
    cut), ``no-config`` (its config.json gone) and ``planner`` (the settings of a planner run)."""
    folder = tmp_path_factory.mktemp("runs")
    config = TrainConfig(
        epochs=1, steps_per_epoch=30, start_steps=10, dataset=str(env_datasets[ARROWS]),
        agent={"batch_size": 8, "hidden": (16,)}, evaluation={"test_episodes": 1, "snapshots": 1},
        replay={"capacity": 2000},
    )  # fmt: skip
    trained = train(config, run_dir=folder / "trained", progress=False)
    for name in ("truncated", "torn", "no-config"):
        shutil.copytree(trained, folder / name)
    checkpoint = folder / "truncated" / "checkpoint.pt"
    checkpoint.write_bytes(checkpoint.read_bytes()[:100])
    log = folder / "torn" / "progress.csv"
    log.write_text(log.read_text()[:-5])
    (folder / "no-config" / "config.json").unlink()
    (folder / "planner").mkdir()
    (folder / "planner" / "config.json").write_text(json.dumps(TrainConfig(algo="planner").to_json()))
    return folder


def _files(folder: Path) -> dict[str, tuple[int, int]]:
    """Every file and folder under ``folder``: its size and time of change (a file rewritten counts)."""
    return {str(p.relative_to(folder)): (p.stat().st_size, p.stat().st_mtime_ns) for p in folder.rglob("*")}


@pytest.mark.parametrize(("argv", "message"), CASES.values(), ids=CASES.keys())
def test_a_user_error_is_one_line_exit_2_and_writes_nothing(
    argv, message, request, tmp_path, monkeypatch, capsys
):
    monkeypatch.chdir(tmp_path)  # nothing may be written, but never into the repository
    monkeypatch.setenv("TACTILE_BRAILLE_DATA", str(tmp_path / "cache"))
    (tmp_path / "file").write_text("not a folder")
    (tmp_path / "rig.json").write_text(json.dumps({}))
    named = {part.removeprefix("{tmp}/").split("/")[0] for part in argv if part.startswith("{tmp}/")}
    if named & set(RUNS):
        runs = request.getfixturevalue("runs")  # trained once, for the cases that name its runs
        for name in named & set(RUNS):
            shutil.copytree(runs / name, tmp_path / name)
    before = _files(tmp_path)
    try:
        code = main([part.replace("{tmp}", str(tmp_path)) for part in argv])
    except SystemExit as exit_:  # argparse's own errors (a usage line, then the error)
        code = exit_.code
    assert code == 2
    error = capsys.readouterr().err
    assert "Traceback" not in error and message in error.splitlines()[-1], error
    assert _files(tmp_path) == before  # no run folder, dataset, .partial or file in a run read


def test_keycaps_named_twice_are_written_and_reported_once(tmp_path, capsys):
    assert main(["keycaps", "--keys", "A,a", "--out", str(tmp_path), "--resolution-mm", "0.5"]) == 0
    assert "wrote 1 STL keycaps" in capsys.readouterr().out
    assert len(list(tmp_path.glob("*.stl"))) == 1


@pytest.mark.parametrize(
    ("error", "message"),
    [
        (OSError(28, "No space left on device"), "No space left on device"),
        (PermissionError(13, "Permission denied"), "Permission denied"),
    ],
    ids=["disk full", "read-only folder"],
)
def test_a_full_disk_or_a_read_only_folder_during_a_run_is_one_line(
    env_datasets, tmp_path, monkeypatch, capsys, error, message
):
    """The machine's faults end in one line too (raised here where the run writes its log: this suite
    runs as root, for whom no folder is read-only)."""
    import tactile_braille.agents.run as run_module

    def failing(path, row):
        raise error

    monkeypatch.setattr(run_module, "append_progress", failing)
    run = tmp_path / "run"
    dataset = str(env_datasets["tactile_braille/DiscreteArrows-v0"])
    argv = ["train", "DiscreteArrows-v0", "--epochs", "1", "--steps-per-epoch", "30", "--start-steps", "10",
            "--test-episodes", "1", "--threads", "1", "--dataset", dataset, "--run-dir", str(run),
            "--quiet"]  # fmt: skip
    assert main(argv) == 2
    captured = capsys.readouterr().err
    assert captured.count("\n") == 1 and message in captured and "Traceback" not in captured
