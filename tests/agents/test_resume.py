"""Run folders are reliable: one writer at a time, and resumes that never drop history.

Each case here failed before the fix it tests: two resumes ran side by side, ``--epochs``
was ignored on a resume, a missing checkpoint restarted the run at epoch 0, and a damaged checkpoint
or replay file ended in a traceback; a progress.csv truncated, torn or edited was reported and
resumed as if whole (epochs dropped from the log).
"""

from __future__ import annotations

import csv
import io
import json
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
import torch

from tactile_braille.agents import TrainConfig, read_progress
from tactile_braille.agents.run import CHECKPOINT_FILE, LOCK_FILE, check_resumable, read_config
from tactile_braille.agents.training import train
from tactile_braille.cli import main

ARROWS = "tactile_braille/DiscreteArrows-v0"


def tiny_run(env_datasets, run_dir: Path, epochs: int) -> Path:
    """A finished DQN run of ``epochs`` epochs of 30 steps, checkpointed after its last epoch."""
    config = TrainConfig(
        epochs=epochs, steps_per_epoch=30, start_steps=10, threads=1, dataset=str(env_datasets[ARROWS]),
        agent={"batch_size": 8, "hidden": (16,)}, evaluation={"test_episodes": 1, "snapshots": 1},
        replay={"capacity": 2000},
    )  # fmt: skip
    return train(config, run_dir=run_dir, progress=False)


@pytest.fixture
def finished_run(env_datasets, tmp_path) -> Path:
    """A finished one-epoch DQN run (checkpointed)."""
    return tiny_run(env_datasets, tmp_path / "run", epochs=1)


def resume(run: Path, *options: str) -> list[str]:
    return ["train", "--resume", str(run), "--quiet", *options]


def one_line_error(capsys) -> str:
    error = capsys.readouterr().err
    assert error.count("\n") == 1 and "Traceback" not in error, error
    return error


def test_a_second_writer_is_refused_and_a_killed_one_leaves_the_run_free(finished_run, capsys):
    # A real training process resumes the run (to many epochs) ...
    script = (
        "from tactile_braille.agents.run import read_config\n"
        "from tactile_braille.agents.training import train\n"
        f"run = {str(finished_run)!r}\n"
        "train(read_config(run).with_changes(epochs=200), run_dir=run, resume=True, progress=False)\n"
    )
    child = subprocess.Popen([sys.executable, "-c", script], stderr=subprocess.PIPE)
    try:
        deadline = time.monotonic() + 60
        while (finished_run / LOCK_FILE).read_text() != f"process {child.pid}":
            assert child.poll() is None, child.stderr.read().decode()
            assert time.monotonic() < deadline, "the resumed run never took its lock"
            time.sleep(0.05)
        # ... and a second resume, meanwhile, is refused at once, naming the first one's process.
        before = (finished_run / "config.json").read_text()
        assert main(resume(finished_run, "--epochs", "300")) == 2
        assert f"is being written by process {child.pid}" in one_line_error(capsys)
        assert (finished_run / "config.json").read_text() == before
    finally:
        os.kill(child.pid, signal.SIGKILL)  # kill -9: the OS releases the lock
        child.wait()
    done = len(read_progress(finished_run))
    assert main(resume(finished_run, "--epochs", str(done + 1))) == 0
    assert [int(row["epoch"]) for row in read_progress(finished_run)] == list(range(done + 1))


def test_resume_extends_with_epochs_and_refuses_any_other_change(finished_run, capsys):
    assert main(resume(finished_run, "--epochs", "2", "--threads", "1")) == 0
    assert [int(row["epoch"]) for row in read_progress(finished_run)] == [0, 1]
    assert read_config(finished_run).epochs == 2
    stored = (finished_run / "config.json").read_text()
    refused = {
        ("--epochs", "1"): "has run 2 epochs already: --epochs 1 cannot shorten it",
        ("--agent.learning-rate", "0.5"): "agent.learning_rate: 0.0005 -> 0.5",
        ("--preset", "fast"): "is a run of preset None, not 'fast'",
    }
    for options, message in refused.items():
        assert main(resume(finished_run, *options)) == 2
        assert message in one_line_error(capsys)
    assert main(["train", "ContinuousArrows-v0", "sac", "--resume", str(finished_run)]) == 2
    assert "is a run of task 'tactile_braille/DiscreteArrows-v0', not" in one_line_error(capsys)
    assert (finished_run / "config.json").read_text() == stored and len(read_progress(finished_run)) == 2


def test_a_resume_whose_checkpoint_is_gone_is_refused_instead_of_starting_again(finished_run, capsys):
    assert main(resume(finished_run, "--epochs", "2")) == 0
    (finished_run / CHECKPOINT_FILE).unlink()
    assert main(resume(finished_run, "--epochs", "3")) == 2
    error = one_line_error(capsys)
    assert "logged 2 epochs but has no checkpoint.pt" in error and "delete" in error
    assert len(read_progress(finished_run)) == 2 and read_config(finished_run).epochs == 2
    # One row and no checkpoint is a run killed between logging its first epoch and checkpointing it:
    # no checkpoint ever existed, so starting again loses nothing saved, and the resume does.
    progress = finished_run / "progress.csv"
    two_rows = progress.read_text()
    progress.write_text("\n".join(two_rows.splitlines()[:2]) + "\n")
    check_resumable(finished_run, read_config(finished_run))
    progress.write_text(two_rows)
    with pytest.raises(ValueError, match="logged 2 epochs"):
        check_resumable(finished_run, read_config(finished_run))


@pytest.mark.parametrize(
    ("damage", "message"),
    [
        (lambda run: _truncate(run / CHECKPOINT_FILE), "checkpoint.pt is unreadable"),
        (lambda run: (run / CHECKPOINT_FILE).write_text("garbage"), "checkpoint.pt is unreadable"),
        (lambda run: _truncate(next(run.glob("replay.*.npz"))), "(the replay buffer checkpoint.pt names)"),
        (lambda run: next(run.glob("replay.*.npz")).unlink(), "(the replay buffer checkpoint.pt names)"),
    ],
    ids=["truncated checkpoint", "garbage checkpoint", "truncated replay", "missing replay"],
)
def test_a_damaged_checkpoint_or_replay_is_refused_in_one_line(finished_run, capsys, damage, message):
    damage(finished_run)
    progress = (finished_run / "progress.csv").read_text()
    assert main(resume(finished_run, "--epochs", "2")) == 2
    assert message in one_line_error(capsys)
    assert (finished_run / "progress.csv").read_text() == progress
    assert read_config(finished_run).epochs == 1  # the refused resume recorded none of its settings


def _truncate(path: Path) -> None:
    data = path.read_bytes()
    path.write_bytes(data[: len(data) // 2])


def test_a_new_run_in_a_folder_held_by_another_writer_is_refused(finished_run, env_datasets, capsys):
    from tactile_braille._io import LockedError, exclusive_lock

    other = finished_run.parent / "other"
    with exclusive_lock(other / LOCK_FILE, "x"), pytest.raises(LockedError, match=f"process {os.getpid()}"):
        # A lock is per open file, so a second taker in this very process is refused too.
        train(TrainConfig(dataset=str(env_datasets[ARROWS])), run_dir=other, progress=False)
    assert not (other / "config.json").exists()
    assert json.loads((finished_run / "config.json").read_text())["epochs"] == 1


def test_a_resume_cleans_a_killed_writers_temporary_files_and_logs_each_step_once(finished_run):
    from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

    stale = finished_run / ".checkpoint.pt.k1ll3d.tmp"  # as atomic_path names them
    stale.write_bytes(b"half a checkpoint")
    assert main(resume(finished_run, "--epochs", "2")) == 0
    assert not stale.exists()
    # Epoch 1 logged, then lost with its checkpoint (as a kill between the two leaves a run): it is
    # run again on the next resume, and TensorBoard keeps only the second run of it.
    kept = {path.name: path.read_bytes() for path in finished_run.iterdir() if path.suffix in (".pt", ".npz")}
    assert main(resume(finished_run, "--epochs", "3")) == 0
    for path in [*finished_run.glob("replay.*.npz"), finished_run / CHECKPOINT_FILE]:
        path.unlink()
    for name, data in kept.items():  # the checkpoint after epoch 1, and its replay
        (finished_run / name).write_bytes(data)
    assert main(resume(finished_run, "--epochs", "3")) == 0
    assert [int(row["epoch"]) for row in read_progress(finished_run)] == [0, 1, 2]
    events = EventAccumulator(str(finished_run))
    events.Reload()
    steps = [event.step for event in events.Scalars("charts/test/episodic_return")]
    assert steps == sorted(set(steps)) == [30, 60, 90]


def test_a_dataset_that_is_neither_a_file_nor_a_default_name_is_refused_before_the_folder(tmp_path, capsys):
    run = tmp_path / "run"
    command = ["train", "ContinuousAlphabet-v0", "sac", "--dataset", "grid-alphabet-6mn", "--quiet"]
    assert main([*command, "--run-dir", str(run)]) != 0
    assert "nor a default dataset's name (" in one_line_error(capsys) and not run.exists()


# ------------------------------------------------------------------ a damaged progress.csv
@pytest.fixture(scope="module")
def _three_epoch_original(env_datasets, tmp_path_factory) -> Path:
    return tiny_run(env_datasets, tmp_path_factory.mktemp("three_epochs") / "run", epochs=3)


@pytest.fixture
def three_epoch_run(_three_epoch_original, tmp_path) -> Path:
    """A finished three-epoch DQN run, checkpointed after its last epoch (a copy of one trained once per
    module: each test may damage its own)."""
    return Path(shutil.copytree(_three_epoch_original, tmp_path / "run"))


def files_of(run: Path) -> dict[str, bytes]:
    """Every file under the run folder (its lock, TensorBoard events and snapshots included)."""
    return {
        str(path.relative_to(run)): path.read_bytes() for path in sorted(run.rglob("*")) if path.is_file()
    }


def _lines(run: Path) -> list[str]:
    return (run / "progress.csv").read_bytes().decode().splitlines(keepends=True)


def _keep_two_rows(run: Path) -> None:
    (run / "progress.csv").write_text("".join(_lines(run)[:3]), newline="")


def _tear_last_row(run: Path) -> None:
    text = (run / "progress.csv").read_bytes().decode()
    (run / "progress.csv").write_text(text[: len(text) - len(_lines(run)[-1]) // 2], newline="")


def _drop_middle_row(run: Path) -> None:
    lines = _lines(run)
    (run / "progress.csv").write_text("".join(lines[:2] + lines[3:]), newline="")


def _edit_a_return(run: Path) -> None:
    rows = list(csv.reader(io.StringIO((run / "progress.csv").read_bytes().decode(), newline="")))
    column = rows[0].index("test/episodic_return")
    rows[2][column] = "2.0" if rows[2][column] != "2.0" else "3.0"  # no return reaches 2: plainly forged
    with open(run / "progress.csv", "w", newline="") as handle:
        csv.writer(handle).writerows(rows)


@pytest.mark.parametrize(
    ("damage", "message"),
    [
        (_keep_two_rows, "has 2 rows, but checkpoint.pt holds epoch 2 (3 rows): rows were lost"),
        (_tear_last_row, "its last row is torn (an incomplete CSV line"),
        (_drop_middle_row, "line 3 logs epoch 2, not 1: rows were lost or repeated"),
        (_edit_a_return, "its first 3 rows differ from those checkpoint.pt recorded"),
    ],
    ids=["truncated to two rows", "torn last row", "a middle row lost", "a return edited"],
)
def test_a_damaged_progress_log_is_refused_by_report_and_resume_changing_nothing(
    three_epoch_run, capsys, damage, message
):
    run = three_epoch_run
    damage(run)
    before = files_of(run)
    assert main(["report", str(run), "--episodes", "1"]) == 2
    error = one_line_error(capsys)
    assert message in error and "restore progress.csv from a backup or start the run again" in error, error
    assert main(resume(run, "--epochs", "4")) == 2
    assert message in one_line_error(capsys)
    assert main(resume(run)) == 2
    assert message in one_line_error(capsys)
    assert files_of(run) == before  # no report, no new settings, no lock taken, no row dropped
    with pytest.raises(ValueError, match=r"restore progress\.csv from a backup"):
        read_progress(run)  # what every report over runs reads


def test_a_torn_row_after_the_checkpoint_can_be_dropped_and_the_run_resumed(finished_run, capsys):
    """A run killed after logging epoch 2 and before checkpointing it, whose last row was then torn (a
    copy cut short): that row is not needed (a resume runs epoch 2 again), and the message says so."""
    run = finished_run
    assert main(resume(run, "--epochs", "2")) == 0
    kept = {name: data for name, data in files_of(run).items() if name.endswith((".pt", ".npz"))}
    assert main(resume(run, "--epochs", "3")) == 0
    for path in [*run.glob("replay.*.npz"), run / CHECKPOINT_FILE]:
        path.unlink()
    for name, data in kept.items():  # the checkpoint after epoch 1, and its replay
        (run / name).write_bytes(data)
    _tear_last_row(run)
    before = files_of(run)
    assert main(["report", str(run), "--episodes", "1"]) == 2
    assert "its last row is torn" in one_line_error(capsys)
    assert main(resume(run)) == 2
    error = one_line_error(capsys)
    assert "its last row is torn" in error and "delete its rows from epoch 2 on and resume" in error, error
    assert files_of(run) == before
    (run / "progress.csv").write_bytes("".join(_lines(run)[:3]).encode())  # as the message says
    assert main(resume(run)) == 0
    assert [int(row["epoch"]) for row in read_progress(run)] == [0, 1, 2]


def test_a_checkpoint_from_before_log_digests_still_resumes_and_reports(three_epoch_run, capsys):
    import torch

    state = torch.load(three_epoch_run / CHECKPOINT_FILE, weights_only=False)
    for key in [key for key in state if key.startswith("progress")]:
        del state[key]
    torch.save(state, three_epoch_run / CHECKPOINT_FILE)
    assert main(["report", str(three_epoch_run), "--episodes", "1"]) == 0
    assert main(resume(three_epoch_run, "--epochs", "4")) == 0
    assert [int(row["epoch"]) for row in read_progress(three_epoch_run)] == [0, 1, 2, 3]


def test_a_resume_whose_log_is_gone_but_whose_checkpoint_covers_epochs_is_refused(three_epoch_run, capsys):
    (three_epoch_run / "progress.csv").unlink()
    before = files_of(three_epoch_run)
    assert main(resume(three_epoch_run, "--epochs", "4")) == 2
    error = one_line_error(capsys)
    assert "has no progress.csv, but its checkpoint.pt holds epoch 2" in error and "from a backup" in error
    assert files_of(three_epoch_run) == before


def test_a_render_run_recorded_as_rig_resumes_and_another_world_is_refused(tmp_path):
    """The render backend's world names itself ``render``; a run recorded before, as ``rig``, is the same
    world and resumes; a record of another backend is still refused."""
    import gymnasium as gym

    from tactile_braille.agents.run import WORLD_FILE, record_world

    env = gym.make(ARROWS, backend="render")
    assert env.unwrapped.world["backend"] == "render"
    record_world(tmp_path, env, resume=False)
    stored = json.loads((tmp_path / WORLD_FILE).read_text())
    (tmp_path / WORLD_FILE).write_text(json.dumps({**stored, "backend": "rig"}))
    record_world(tmp_path, env, resume=True)  # no error: the same world under its former name
    (tmp_path / WORLD_FILE).write_text(json.dumps({**stored, "backend": "dataset"}))
    with pytest.raises(ValueError, match="trained in another world"):
        record_world(tmp_path, env, resume=True)


# ---------------------------------------------------------------- exact resumes
EXACT = TrainConfig(
    epochs=4, steps_per_epoch=30, start_steps=10, threads=1, seed=1, precision="fp32",
    agent={"batch_size": 8, "hidden": (16,)}, evaluation={"test_episodes": 2, "snapshots": 1},
    replay={"capacity": 2000}, keep_pose_fraction=0.9,
)  # fmt: skip
"""Epochs of 30 steps and episodes of up to 25: most checkpoints fall inside an episode; nine in
ten episodes after the first keep the pose the last one left (the reset a resume must put back)."""
KILLS = {
    "mid-episode, epoch 1": "Episodes.step", "mid-episode, epoch 2": "Episodes.step",
    "between a row and its checkpoint": "EpochLog.write", "mid-checkpoint": "EpisodeReplayBuffer.save",
}  # fmt: skip
AT = {"mid-episode, epoch 1": 47, "mid-episode, epoch 2": 71, "between a row and its checkpoint": 3,
      "mid-checkpoint": 2}  # fmt: skip
"""The call of the patched function after which the process kills itself (kill -9)."""


def _kill_at(run: Path, config: TrainConfig, where: str, call: int) -> None:
    """Train ``config`` into ``run`` in a process that kills itself with SIGKILL right after the
    ``call``-th call of ``where`` (a function of the loop), as ``kill -9`` would at that moment."""
    script = f"""
import json, os, signal
from tactile_braille.agents import training, replay, run as run_module
from tactile_braille.agents.config import TrainConfig
owner = {{"Episodes": training.Episodes, "EpochLog": run_module.EpochLog,
          "EpisodeReplayBuffer": replay.EpisodeReplayBuffer}}[{where.split(".")[0]!r}]
original, calls = getattr(owner, {where.split(".")[1]!r}), [0]
def patched(*args, **kwargs):
    result = original(*args, **kwargs)
    calls[0] += 1
    if calls[0] == {call}:
        os.kill(os.getpid(), signal.SIGKILL)
    return result
setattr(owner, {where.split(".")[1]!r}, patched)
config = TrainConfig.from_json(json.loads({json.dumps(config.to_json())!r}))
training.train(config, run_dir={str(run)!r}, progress=False)
"""
    child = subprocess.run([sys.executable, "-c", script], capture_output=True, timeout=300)
    assert child.returncode == -signal.SIGKILL, child.stderr.decode()[-2000:]


def _rows_but_time(run: Path) -> list[dict]:
    return [{k: v for k, v in row.items() if k not in ("charts/SPS", "time_s")} for row in read_progress(run)]


@pytest.mark.slow
def test_a_run_killed_anywhere_and_resumed_logs_the_uninterrupted_runs_rows(env_datasets, tmp_path):
    """Killed with -9 inside an episode, between logging an epoch and checkpointing it, or while
    checkpointing, and resumed: every column of progress.csv but the timings is the uninterrupted run's."""
    config = EXACT.with_changes(dataset=str(env_datasets[ARROWS]))
    whole = train(config, run_dir=tmp_path / "whole", progress=False)
    expected = _rows_but_time(whole)
    assert len(expected) == 4
    kept = []
    for name, where in KILLS.items():
        run = tmp_path / name.replace(" ", "_").replace(",", "")
        _kill_at(run, config, where, AT[name])
        episode = torch.load(run / CHECKPOINT_FILE, weights_only=False)["episode"]
        kept.append(episode["kept_pose"] is not None)
        assert episode["actions"], f"{name}: the checkpoint holds no episode in progress to resume"
        train(run_dir=run, resume=True, progress=False)
        assert _rows_but_time(run) == expected, name
    assert any(kept), "no resumed episode had kept its pose: the kept-pose reset went untested"


def test_a_resume_on_other_samples_of_the_same_dataset_parameters_is_refused(finished_run, tmp_path, capsys):
    """The run's world record holds its dataset's samples digest: a dataset of the same parameters whose
    frames differ (here mirrored, its digest made anew) is another world."""
    import h5py

    from tactile_braille.datasets.store import samples_digest

    assert "samples_sha256" in json.loads((finished_run / "world.json").read_text())
    other = tmp_path / "mirrored.h5"
    shutil.copyfile(read_config(finished_run).dataset, other)
    with h5py.File(other, "r+") as handle:
        frames = handle["observations"][()][:, :, ::-1]
        del handle["observations"]
        handle.create_dataset("observations", data=frames)
        names = ("observations", "poses", "labels", "pressed", "tap_index")
        handle.attrs["samples_sha256"] = samples_digest({name: handle[name][()] for name in names})
    assert main(resume(finished_run, "--dataset", str(other), "--epochs", "2")) == 2
    assert "was trained in another world than this one (samples_sha256:" in one_line_error(capsys)
