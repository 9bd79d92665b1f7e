"""This project's agents tuned by the benchmark's protocol (:mod:`tactile_braille.search`), as every
method on the leaderboard is.

An agent's search space is its hyperparameter class's ``search_space``
(:class:`~tactile_braille.agents.config.AgentConfig`); the untuned settings are a preset's. A trial
is a training run of the preset with the trial's settings on a tuning seed, for the preset's epochs
(or ``epochs``), typed under the paper's protocol after a third and two thirds of its steps (median
pruning) and at its end. The final runs train the best trial's settings on fresh seeds; each run
folder holds the search's record (``tuning.json``), so its results file carries it and the
leaderboard names the method ``... (`PRESET`, tuned: name=value, ...)`` with its trials.

    tactile-braille tune search DiscreteArrows-v0 planner --preset fast-tactile --trials 16 --study runs/tune
    tactile-braille tune run DiscreteArrows-v0 planner --preset fast-tactile --study runs/tune \\
        --seeds 0 1 2 3 4 --root runs/tuned --into results/tuned

A search's study is ``STUDY/TASK__ALGO__PRESET.db``, its record the ``.json`` beside it; each trial
trains in a folder of its own under ``STUDY/trials/``, removed once the trial is scored. A final run
that stops resumes from its last checkpoint when the command is given again; two processes can share
the seeds (a run being trained by one is left to it).
"""

from __future__ import annotations

import json
import shutil
import tempfile
import time
from pathlib import Path
from typing import Any

from tactile_braille import search as protocol
from tactile_braille._io import LockedError, atomic_path
from tactile_braille.agents.config import TrainConfig
from tactile_braille.agents.presets import preset_config
from tactile_braille.agents.registry import agent_spec
from tactile_braille.agents.run import MACHINE_SETTINGS
from tactile_braille.envs.registry import task_name
from tactile_braille.search import TUNING_SEEDS, Space

MACHINE = (*MACHINE_SETTINGS, "precision")
"""The settings a search or its final runs may be given on top of the preset and the searched ones:
where and how long they run (``epochs``), and the numbers' precision."""


def search_space(algo: str) -> Space:
    """The agent's search space; an agent without one is refused."""
    space = agent_spec(algo).config.search_space
    if not space:
        raise ValueError(
            f"{algo} has no search space ({agent_spec(algo).config.__name__}.search_space is empty): "
            "give its hyperparameter class one to tune it"
        )
    return space


def _task(task: str) -> str:
    return task if "/" in task else f"tactile_braille/{task}"


def _config(task: str, algo: str, preset: str, seed: int, settings: dict, machine: dict) -> TrainConfig:
    unknown = sorted(set(machine) - set(MACHINE))
    if unknown:
        raise ValueError(f"{unknown} are not machine settings; a search changes only {list(MACHINE)} beside "
                         "the searched ones")  # fmt: skip
    return preset_config(preset, _task(task), algo, seed=seed, agent=settings, **machine)


def _identity(task: str, algo: str, preset: str) -> dict:
    return {"library": "tactile_braille", "algo": algo, "preset": preset, "task": task_name(_task(task))}


def _study_path(study_dir: Path, task: str, algo: str, preset: str) -> Path:
    return Path(study_dir) / f"{task_name(_task(task))}__{algo}__{preset}.db"


def untuned(task: str, algo: str, preset: str) -> dict[str, Any]:
    """The preset's values of the agent's searched settings on ``task``."""
    agent = preset_config(preset, _task(task), algo).agent
    return {name: json.loads(json.dumps(getattr(agent, name))) for name in search_space(algo)}


def tune(
    task: str,
    algo: str,
    preset: str,
    trials: int,
    study_dir: Path,
    seeds=(TUNING_SEEDS[0],),
    machine: dict | None = None,
) -> dict:
    """Search the agent's settings on ``task`` from ``preset`` until the study holds ``trials`` finished
    or pruned trials (:func:`tactile_braille.search.search`); returns the search's record, also written
    beside the study. Each trial trains on each of the tuning ``seeds`` in turn and scores their mean.
    ``machine``: :data:`MACHINE` settings of every run (``epochs``: each run's length, the preset's by
    default)."""
    from tactile_braille.agents.training import make_env, train

    machine = dict(machine or {})
    for seed in seeds:
        protocol.check_tuning_seed(seed)
    space = search_space(algo)
    base = _config(task, algo, preset, seeds[0], {}, machine)  # settings refused before a study is made
    steps = base.epochs * base.steps_per_epoch
    trial_root = Path(study_dir) / "trials"

    def train_and_score(settings: dict, seed: int, check) -> tuple[Any, float]:
        config = _config(task, algo, preset, seed, settings, machine)
        points = list(protocol.check_points(steps))
        trial_root.mkdir(parents=True, exist_ok=True)
        folder = Path(tempfile.mkdtemp(prefix="trial-", dir=trial_root))
        trained: dict[str, Any] = {}

        def after_epoch(env_steps: int, agent) -> None:
            trained["agent"] = agent
            while points and env_steps >= points[0]:
                points.pop(0)
                check(env_steps, _typing(config, agent, make_env))

        started = time.perf_counter()
        try:
            train(config, run_dir=folder, progress=False, after_epoch=after_epoch)
            minutes = (time.perf_counter() - started) / 60
            return _typing(config, trained["agent"], make_env), minutes
        finally:
            shutil.rmtree(folder, ignore_errors=True)

    return protocol.search(_study_path(study_dir, task, algo, preset), _identity(task, algo, preset), space,
                  untuned(task, algo, preset), trials, seeds, steps, train_and_score)  # fmt: skip


def _typing(config: TrainConfig, agent, make_env):
    """The agent typing the paper's sequences under its run's conditions (no sentences)."""
    from tactile_braille.evaluation.scoring import evaluate_policy

    return evaluate_policy(agent, config.task, env=make_env(config), track=config.track, sentences=False,
                           max_episode_steps=config.max_episode_steps)  # fmt: skip


def search_record(study_dir: Path, task: str, algo: str, preset: str) -> dict:
    """The finished search of ``algo`` from ``preset`` on ``task``: from its study in ``study_dir``, or
    else from the record written beside it (:func:`tactile_braille.search.finished_search`)."""
    return protocol.finished_search(_study_path(study_dir, task, algo, preset), _identity(task, algo, preset),
                           search_space(algo), untuned(task, algo, preset))  # fmt: skip


def run_seeds(
    task: str,
    algo: str,
    preset: str,
    study_dir: Path,
    seeds,
    root: Path,
    into: Path,
    machine: dict | None = None,
) -> list[Path]:
    """Train the best trial's settings on each of ``seeds`` (none a tuning seed) in
    ``root/TASK__ALGO__tuned__SEED``, type with each and archive its record in ``into``; returns the
    archived records. A seed whose record is in ``into`` is not run again; a run stopped part way
    resumes from its last checkpoint; a run another process is training is left to it."""
    from tactile_braille.agents.run import read_progress
    from tactile_braille.agents.training import train
    from tactile_braille.evaluation.runs import TUNING_FILE, evaluate_typing
    from tactile_braille.sweep import archive_run

    protocol.check_reported_seeds(seeds)
    machine = dict(machine or {})
    tuning = search_record(study_dir, task, algo, preset)
    settings = tuning["best"]["params"]
    configs = {seed: _config(task, algo, preset, seed, settings, machine) for seed in seeds}  # checked first
    written = []
    for seed, config in configs.items():
        run_dir = Path(root) / f"{task_name(config.task)}__{algo}__tuned__{seed}"
        record = Path(into) / run_dir.name
        if (record / "result.json").exists() and len(read_progress(record)) == config.epochs:
            written.append(record)
            continue
        started = (run_dir / "config.json").exists()  # resumed (a change of settings is refused)
        run_dir.mkdir(parents=True, exist_ok=True)
        with atomic_path(run_dir / TUNING_FILE) as temporary:
            temporary.write_text(json.dumps(tuning, indent=2, default=protocol.json_value) + "\n")
        try:
            train(config, run_dir=run_dir, resume=started, progress=False)
        except LockedError:
            continue  # another process trains this seed
        evaluate_typing(run_dir)
        written.append(archive_run(run_dir, into))
    return written
