"""The command line as a user meets it: defaults that fit a shared machine, help that says what an
option needs, a policy module imported from the current folder, reports that write only where told
and say when a run did not converge, and a refused warm start that names what differs first.

Each test failed before the change it covers (the errors' own cases are in test_cli_errors.py).
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import pytest
import torch

from tactile_braille.agents import TrainConfig, common, train
from tactile_braille.agents.report import convergence_cell, write_report
from tactile_braille.cli import _resume_config, _train_config, build_parser, main
from tactile_braille.cli_config import resolve_precision

ARROWS = "tactile_braille/DiscreteArrows-v0"


def _files(folder: Path) -> dict[str, tuple[int, int]]:
    """Every file and folder under ``folder``: its size and time of change (a file rewritten counts)."""
    return {str(p.relative_to(folder)): (p.stat().st_size, p.stat().st_mtime_ns) for p in folder.rglob("*")}


@pytest.fixture(scope="module")
def evaluated_run(env_datasets, tmp_path_factory) -> Path:
    """A finished one-epoch DQN run with its typing evaluation (``tactile-braille evaluate RUN``)."""
    config = TrainConfig(
        epochs=1, steps_per_epoch=30, start_steps=10, dataset=str(env_datasets[ARROWS]),
        agent={"batch_size": 8, "hidden": (16,)}, evaluation={"test_episodes": 1, "snapshots": 1},
        replay={"capacity": 2000},
    )  # fmt: skip
    run = train(config, run_dir=tmp_path_factory.mktemp("evaluated") / "run", progress=False)
    assert main(["evaluate", str(run)]) == 0
    return run


def test_report_with_output_writes_there_and_nothing_in_the_runs_it_reads(evaluated_run, tmp_path, capsys):
    before = _files(evaluated_run)
    assert main(["report", str(evaluated_run), "--output", str(tmp_path / "out")]) == 0
    assert "wrote" in capsys.readouterr().out
    assert _files(evaluated_run) == before  # no report.md, curve.png, typing.json or result.json there
    assert (tmp_path / "out" / "results.md").exists()


def test_a_policy_module_in_the_current_folder_imports_as_under_python_m(
    env_datasets, tmp_path, monkeypatch, capsys
):
    """The ``tactile-braille`` script's own folder leads ``sys.path``, not the current one."""
    (tmp_path / "cwd_policy_mine.py").write_text("def press(observation):\n    return 4\n")
    monkeypatch.chdir(tmp_path)
    monkeypatch.setattr(sys, "path", [entry for entry in sys.path if entry not in ("", ".", str(tmp_path))])
    before = list(sys.path)
    output = tmp_path / "press.json"
    argv = ["evaluate", "DiscreteArrows-v0", "--policy", "cwd_policy_mine:press", "--method", "always press",
            "--dataset", str(env_datasets[ARROWS]), "--output", str(output)]  # fmt: skip
    try:
        assert main(argv) == 0, capsys.readouterr().err
    finally:
        sys.modules.pop("cwd_policy_mine", None)
    assert json.loads(output.read_text())["method"] == "always press"
    assert sys.path == before  # the current folder was on it for the evaluation only


def test_evaluate_help_says_what_policy_needs(capsys):
    with pytest.raises(SystemExit):
        main(["evaluate", "--help"])
    text = " ".join(capsys.readouterr().out.split())
    assert "--method METHOD required with --policy" in text
    assert "--output OUTPUT required with --policy" in text


def test_a_run_that_never_reached_095_has_not_converged_in_its_report(tmp_path, monkeypatch):
    """A planner run whose best test return was 0.90: 95 % of that is reached at epoch 1, which the
    report gave as its convergence epoch."""
    import tactile_braille.agents.report as report_module

    run = tmp_path / "run"
    run.mkdir()
    (run / "config.json").write_text(json.dumps(TrainConfig(algo="planner").to_json()))
    header = "epoch,env_steps,updates,train/episodic_return,test/episodic_return,time_s\n"
    rows = "".join(
        f"{epoch},{250 * (epoch + 1)},0,0.5,{value},1.0\n" for epoch, value in enumerate([0.9, 0.85, 0.9])
    )
    (run / "progress.csv").write_text(header + rows)
    torch.save({"epoch": 2, "env_steps": 750, "updates": 0, "agent": {}}, run / "checkpoint.pt")
    final = {"test/episodic_return": 0.9, "test/success_rate": 0.9, "test/episode_length": 3.0}
    monkeypatch.setattr(report_module, "evaluate_run", lambda run_dir, episodes: final)
    text = write_report(run, episodes=1).read_text()
    row = (
        "| convergence epoch, paper's rule (95 % of the best) | 1 (of a best test return of 0.90: 0.95 never"
    )
    assert row in text
    assert "| first epoch with test return >= 0.95 | not reached |" in text
    # A run that reached 0.95 keeps the paper's epoch: 95 % of its best, 0.97, first at epoch 2.
    assert convergence_cell([0.5, 0.93, 0.97]) == "2"
    assert convergence_cell([0.9, 0.85, 0.9]) == "1 (of a best test return of 0.90: 0.95 never reached)"


@pytest.mark.parametrize("native", [False, True], ids=["no native bf16", "native bf16"])
def test_auto_precision_is_bf16_only_where_the_device_computes_it_natively(monkeypatch, native):
    monkeypatch.setattr(common, "native_bf16", lambda device: native)
    wanted = "bf16" if native else "fp32"
    assert resolve_precision("auto", "cpu") == wanted
    assert (resolve_precision("fp32", "cpu"), resolve_precision("bf16", "cpu")) == ("fp32", "bf16")
    # A new run's default, and `auto` given: chosen before the settings are recorded.
    for options in ([], ["--precision", "auto"]):
        config = _train_config(build_parser().parse_args(["train", "DiscreteArrows-v0", *options]))
        assert config.precision == wanted and config.to_json()["precision"] == wanted
    given = _train_config(build_parser().parse_args(["train", "DiscreteArrows-v0", "--precision", "fp32"]))
    assert given.precision == "fp32"


def test_train_help_documents_auto_precision(capsys):
    with pytest.raises(SystemExit):
        main(["train", "--help"])
    text = " ".join(capsys.readouterr().out.split())
    assert "--precision {fp32,bf16,auto}" in text and "Or auto, the default of a new run: bf16 where" in text


def test_a_run_takes_one_torch_thread_unless_told_and_older_runs_resume_as_recorded(tmp_path):
    assert TrainConfig().threads == 1
    assert _train_config(build_parser().parse_args(["train", "DiscreteArrows-v0"])).threads == 1
    assert build_parser().parse_args(["classify"]).threads == 1
    run = tmp_path / "run"  # a run recorded with the former defaults: two threads, and bf16
    run.mkdir()
    (run / "config.json").write_text(json.dumps(TrainConfig(threads=2, precision="bf16").to_json()))
    for options in ([], ["--precision", "auto"]):  # nothing to change: the stored settings go on
        assert _resume_config(build_parser().parse_args(["train", "--resume", str(run), *options])) is None
    resumed = _resume_config(build_parser().parse_args(["train", "--resume", str(run), "--threads", "1"]))
    assert (resumed.threads, resumed.precision) == (1, "bf16")


def test_a_refused_warm_start_leads_with_what_differs_in_a_short_line(tmp_path, capsys):
    planner, dqn = tmp_path / "planner", tmp_path / "dqn"
    other_dqn = TrainConfig(taps=2, agent={"hidden": (16,), "batch_size": 8, "gamma": 0.5})
    for source, config in ((planner, TrainConfig(algo="planner")), (dqn, other_dqn)):
        source.mkdir()
        (source / "config.json").write_text(json.dumps(config.to_json()))
    for source in (planner, dqn):
        argv = [
            "train",
            "DiscreteArrows-v0",
            "dqn",
            "--init-from",
            str(source),
            "--run-dir",
            str(tmp_path / "warm"),
        ]
        assert main(argv) == 2
        error = capsys.readouterr().err
        assert error.count("\n") == 1 and len(error) < 350 + len(str(source)), error
        assert not (tmp_path / "warm").exists()
        if source == planner:  # another algorithm: its hyperparameters all differ, unlisted
            assert f"{planner} learnt with other settings (algo: 'planner' -> 'dqn';" in error
            assert "agent." not in error
        else:  # top-level settings first, then at most three in all
            assert "taps: 2 -> 1; " in error and error.index("taps") < error.index("agent.")
            assert "more)" in error
