"""Sweeps: planning, resumable sequential runs with retries, and two tiny trials on a local Ray."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from tactile_braille.agents import read_progress
from tactile_braille.cli import main
from tactile_braille.evaluation.report import load_records
from tactile_braille.sweep import Trial, archive_run, plan, run_trial, sweep

TINY = {
    "epochs": 1,
    "steps_per_epoch": 30,
    "start_steps": 20,
    "threads": 1,
    "updates_per_step": 1,
    "evaluation": {"test_episodes": 1},
    "replay": {"capacity": 500},
    "agent": {"batch_size": 8, "hidden": (16,)},
}


def test_plan_pairs_algorithms_with_matching_tasks():
    trials = plan(["DiscreteArrows-v0", "ContinuousArrows-v0"], ["dqn", "sac"], [0, 1], epochs=3)
    assert [t.name for t in trials] == [
        "DiscreteArrows-v0__dqn__0", "DiscreteArrows-v0__dqn__1",
        "ContinuousArrows-v0__sac__0", "ContinuousArrows-v0__sac__1",
    ]  # fmt: skip
    assert trials[0].config().epochs == 3 and trials[2].config().agent.gamma == 0.95
    with pytest.raises(ValueError, match="unknown algorithm"):
        plan(["DiscreteArrows-v0"], ["ppo"], [0])
    with pytest.raises(ValueError, match="no algorithm"):
        plan(["DiscreteArrows-v0"], ["sac"], [0])
    with pytest.raises(ValueError, match="epochs"):
        plan(["DiscreteArrows-v0"], ["dqn"], [0], epochs=0)  # bad settings fail before any trial


def test_plan_names_a_variant_and_gives_each_algorithm_its_settings():
    settings = {"dqn": {"agent": {"batch_size": 64}}}
    trials = plan(["DiscreteArrows-v0", "ContinuousArrows-v0"], ["dqn", "sac"], [7],
                  variant="relabel-all_b64", settings=settings, replay={"relabel": "all"},
                  agent={"gamma": 0.9})  # fmt: skip
    assert [t.name for t in trials] == [
        "DiscreteArrows-v0__dqn__relabel-all_b64__7",
        "ContinuousArrows-v0__sac__relabel-all_b64__7",
    ]
    dqn, sac = (t.config() for t in trials)
    assert (dqn.agent.batch_size, dqn.agent.gamma, dqn.replay.relabel) == (64, 0.9, "all")  # groups merged
    assert sac.replay.relabel == "all" and sac.agent.batch_size != 64  # the DQN's setting only
    for bad in ("a__b", "a/b", "_a", "a b", "..", "-x"):
        with pytest.raises(ValueError, match="variant"):
            plan(["DiscreteArrows-v0"], ["dqn"], [0], variant=bad)


def test_sequential_sweep_is_resumable_and_retries(env_datasets, tmp_path, monkeypatch):
    dataset = str(env_datasets["tactile_braille/DiscreteArrows-v0"])
    trials = plan(["DiscreteArrows-v0"], ["dqn"], [0, 1], dataset=dataset, **TINY)
    runs = sweep(trials, tmp_path, use_ray=False, progress=False)
    assert [len(read_progress(run)) for run in runs] == [1, 1]
    before = (runs[0] / "progress.csv").read_text()
    sweep(trials, tmp_path, use_ray=False, progress=False)  # finished trials return at once
    assert (runs[0] / "progress.csv").read_text() == before
    other = plan(["DiscreteArrows-v0"], ["dqn"], [0], dataset=dataset, **{**TINY, "precision": "bf16"})
    with pytest.raises(ValueError, match=r"other settings \(precision: 'fp32' -> 'bf16'\)"):
        sweep(other, tmp_path, use_ray=False, progress=False)
    longer = plan(["DiscreteArrows-v0"], ["dqn"], [0], dataset=dataset, **{**TINY, "epochs": 2})
    sweep(longer, tmp_path, use_ray=False, progress=False)  # more epochs extend the run
    assert len(read_progress(runs[0])) == 2

    from tactile_braille import sweep as sweep_module

    calls = []

    def flaky(trial, root, progress=False):
        calls.append(trial.name)
        if len(calls) == 1:
            raise RuntimeError("the robot lost power")
        return run_trial(trial, root, progress)

    monkeypatch.setattr(sweep_module, "run_trial", flaky)
    more = [Trial("DiscreteArrows-v0", "dqn", 2, "paper", {**TINY, "dataset": dataset})]
    sweep(more, tmp_path, use_ray=False, progress=False, max_failures=1)
    assert calls == ["DiscreteArrows-v0__dqn__2"] * 2
    assert len(read_progress(tmp_path / "DiscreteArrows-v0__dqn__2")) == 1

    def broken(trial, root, progress=False):
        raise RuntimeError("always")

    monkeypatch.setattr(sweep_module, "run_trial", broken)
    with pytest.raises(RuntimeError, match="failed 2 times"):
        sweep(more, tmp_path, use_ray=False, progress=False, max_failures=1)


def test_trials_run_side_by_side_and_archived_ones_are_not_run_again(env_datasets, tmp_path):
    dataset = str(env_datasets["tactile_braille/DiscreteArrows-v0"])
    trials = plan(["DiscreteArrows-v0"], ["dqn"], [0, 1], dataset=dataset, **TINY)
    archive = tmp_path / "results"
    runs = sweep(trials, tmp_path / "machine1", use_ray=False, progress=False, jobs=2, archive=archive)
    assert [len(read_progress(run)) for run in runs] == [1, 1]
    for trial, run in zip(trials, runs, strict=True):
        record = archive / trial.name
        assert sorted(p.name for p in record.iterdir()) == ["config.json", "progress.csv", "result.json",
                                                            "typing.json", "world.json"]  # fmt: skip
        assert (record / "progress.csv").read_text() == (run / "progress.csv").read_text()
        typing = json.loads((record / "typing.json").read_text())
        assert typing["checkpoint_epoch"] == 0 and "released_protocol" in typing
    # A new machine: the run folders are gone, the archive was committed. Nothing is run again,
    # and the sweep answers with the archived records, which a report reads.
    again = sweep(trials, tmp_path / "machine2", use_ray=False, progress=False, jobs=2, archive=archive)
    assert again == [archive / trial.name for trial in trials]
    assert not (tmp_path / "machine2" / trials[0].name).exists()
    records = load_records(again, evaluate_missing=False)
    assert [r.typing["checkpoint_epoch"] for r in records] == [0, 0]
    assert main(["report", *map(str, again), "--output", str(tmp_path / "report")]) == 0
    assert "| disc arrow | DQN (paper, fp32," in (tmp_path / "report" / "results.md").read_text()
    # More epochs than archived: the trial runs (here from scratch, its checkpoint being elsewhere).
    longer = plan(["DiscreteArrows-v0"], ["dqn"], [0], dataset=dataset, **{**TINY, "epochs": 2})
    [run] = sweep(longer, tmp_path / "machine2", use_ray=False, progress=False, archive=archive)
    assert len(read_progress(run)) == 2 and len(read_progress(archive / trials[0].name)) == 2
    with pytest.raises(ValueError, match="jobs must be at least 1"):
        sweep(trials, tmp_path, use_ray=False, jobs=0)
    # An archive never loses a record: other settings are refused before anything runs, a shorter
    # record does not replace a longer one; where a run was made (threads, device) does not matter.
    other = plan(["DiscreteArrows-v0"], ["dqn"], [1], dataset=dataset, **{**TINY, "precision": "bf16"})
    with pytest.raises(ValueError, match=r"other settings \(precision"):
        sweep(other, tmp_path / "machine3", use_ray=False, progress=False, archive=archive)
    assert not (tmp_path / "machine3" / other[0].name).exists()
    with pytest.raises(ValueError, match="holds a longer record"):
        archive_run(runs[0], archive)
    elsewhere = plan(["DiscreteArrows-v0"], ["dqn"], [1], dataset=dataset, **{**TINY, "threads": 2})
    assert sweep(elsewhere, tmp_path / "machine3", use_ray=False, progress=False, archive=archive) == [
        archive / trials[1].name
    ]


@pytest.mark.slow
def test_two_tiny_trials_on_a_local_ray(env_datasets, tmp_path):
    """About a minute alone (Ray's start and two workers importing torch); `make test-slow`."""
    pytest.importorskip("ray")
    dataset = str(env_datasets["tactile_braille/DiscreteArrows-v0"])
    trials = plan(["DiscreteArrows-v0"], ["dqn"], [0, 1], dataset=dataset, **TINY)
    runs = sweep(trials, tmp_path, use_ray=True, cpus_per_trial=1, progress=False)
    for run, seed in zip(runs, (0, 1), strict=True):
        rows = read_progress(run)
        assert len(rows) == 1 and rows[0]["env_steps"] == 30
        assert f"__{seed}" in run.name


@pytest.mark.slow
def test_trials_run_on_a_ray_cluster_given_by_its_address(env_datasets, tmp_path):
    """A Ray cluster started apart (``ray start --head``, as on a cluster's head machine), the sweep joining
    it by ``address``: the recipe of docs/evaluation.md on one machine. Every node must see ``root``.
    ``ray stop`` at the end stops every Ray of this machine: run it where no other Ray is wanted."""
    pytest.importorskip("ray")
    import shutil
    import socket
    import subprocess
    import sys

    ray_command = shutil.which("ray", path=str(Path(sys.executable).parent))
    assert ray_command, "Ray's command line comes with the sweep extra"
    with socket.socket() as probe:  # a free port for the head
        probe.bind(("127.0.0.1", 0))
        port = probe.getsockname()[1]
    head = [ray_command, "start", "--head", f"--port={port}", "--num-cpus=2", "--include-dashboard=false"]
    subprocess.run(head, check=True, capture_output=True, timeout=120)
    try:
        dataset = str(env_datasets["tactile_braille/DiscreteArrows-v0"])
        trials = plan(["DiscreteArrows-v0"], ["dqn"], [0, 1], dataset=dataset, **TINY)
        runs = sweep(trials, tmp_path / "root", use_ray=True, address=f"127.0.0.1:{port}", cpus_per_trial=1,
                     progress=False)  # fmt: skip
        assert [len(read_progress(run)) for run in runs] == [1, 1]
    finally:
        subprocess.run([ray_command, "stop", "--force"], capture_output=True, timeout=120)


def test_ray_asked_for_but_not_installed_is_refused_before_anything_is_made(tmp_path, monkeypatch):
    import tactile_braille.sweep as sweep_module

    monkeypatch.setattr(sweep_module, "ray_available", lambda: False)
    trials = plan(["DiscreteArrows-v0"], ["dqn"], [0], "fast", epochs=1)
    with pytest.raises(ValueError, match=r"--ray yes needs Ray: pip install 'tactile_braille\[sweep\]'"):
        sweep(trials, tmp_path / "root", use_ray=True, progress=False)
    assert not (tmp_path / "root").exists()
