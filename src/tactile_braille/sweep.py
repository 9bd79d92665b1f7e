"""Sweeps: tasks x algorithms x seeds, on Ray Tune when it is installed, one after another otherwise.

Every trial is an ordinary training run in ``ROOT/{task}__{algo}__{seed}``
(``ROOT/{task}__{algo}__{variant}__{seed}`` for a variant of a preset).
A trial whose folder holds a run is resumed (a finished one returns at once),
so a sweep is resumable as a whole: run the same command again after a crash.
Failed trials are retried (``max_failures`` times), each retry resuming from
the trial's last checkpoint. Without Ray, ``jobs`` trials run side by side,
each in its own process (``tactile-braille sweep ... --jobs 14`` on a 16-core
GPU machine, each trial on one thread, all sharing the GPU with ``--device
cuda``).

Results outlive the machine through an **archive** (``archive=DIR``,
``--archive``): each finished trial's typing is evaluated (:func:`archive_run`)
and its record, the small files that a report needs (settings, world, progress
log, typing evaluation; no checkpoint), is copied to ``DIR/<name>``, a folder
meant to be committed. A trial whose archived record is complete is not run
again, even on a new machine whose run folders are gone; one archived part way
(``tactile-braille archive RUN_DIR --into DIR`` before a machine is given back)
is shown in reports as far as it went. With Ray (``pip install tactile_braille[sweep]``)
trials run in parallel on the local machine, or on a cluster with
``address="ray://..."``; each trial asks for ``cpus_per_trial`` CPUs.

>>> [t.name for t in plan(["DiscreteArrows-v0"], ["dqn", "sac"], [0, 1])]
['DiscreteArrows-v0__dqn__0', 'DiscreteArrows-v0__dqn__1']
"""

from __future__ import annotations

import dataclasses
import importlib.util
import json
import multiprocessing
import re
import shutil
from collections.abc import Sequence
from concurrent.futures import FIRST_EXCEPTION, ProcessPoolExecutor, wait
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from tactile_braille._io import atomic_path
from tactile_braille.agents.config import differences
from tactile_braille.agents.presets import preset_config
from tactile_braille.agents.registry import agent_spec
from tactile_braille.agents.run import MACHINE_SETTINGS, read_config, read_progress, setting_differences
from tactile_braille.agents.training import train
from tactile_braille.envs.registry import task_of

PAPER_SIM_RUNS = (
    ("DiscreteArrows-v0", "dqn"), ("DiscreteArrows-v0", "sac_discrete"),
    ("DiscreteAlphabet-v0", "dqn"), ("DiscreteAlphabet-v0", "sac_discrete"),
    ("ContinuousArrows-v0", "td3"), ("ContinuousArrows-v0", "sac"),
    ("ContinuousAlphabet-v0", "td3"), ("ContinuousAlphabet-v0", "sac"),
)  # fmt: skip
"""The simulated rows of the paper's Table III."""


VARIANT_NAME = re.compile(r"[A-Za-z0-9][A-Za-z0-9.-]*(_[A-Za-z0-9.-]+)*")
"""A variant's name: a letter or digit first, no '__' (the separator of a trial's name), no path
characters."""


@dataclass(frozen=True)
class Trial:
    """One training run of a sweep."""

    task: str
    algo: str
    seed: int
    preset: str = "paper"
    overrides: dict[str, Any] = field(default_factory=dict)
    variant: str = ""
    """Names the overrides in the trial's folder (``{task}__{algo}__{variant}__{seed}``), so that runs
    of a preset and of its variants can share a root and an archive."""

    @property
    def name(self) -> str:
        middle = f"__{self.variant}" if self.variant else ""
        return f"{self.task}__{self.algo}{middle}__{self.seed}"

    @property
    def env_id(self) -> str:
        return self.task if "/" in self.task else f"tactile_braille/{self.task}"

    def config(self):
        return preset_config(self.preset, self.env_id, self.algo, seed=self.seed, **dict(self.overrides))


def plan(
    tasks: Sequence[str],
    algos: Sequence[str],
    seeds: Sequence[int],
    preset: str = "paper",
    variant: str = "",
    settings: dict[str, dict[str, Any]] | None = None,
    **overrides: Any,
) -> list[Trial]:
    """Every (task, algo, seed) whose action kinds match (DQN on discrete tasks, SAC on continuous...).

    ``overrides`` change every trial's settings, ``settings[algo]`` those of one algorithm's trials
    (as :func:`~tactile_braille.agents.config.replace_settings` takes them); ``variant`` names them.
    """
    if variant and not VARIANT_NAME.fullmatch(variant):
        raise ValueError(f"variant {variant!r}: use letters, digits, '.', '-' and single '_' (it names "
                         "folders whose parts '__' separates)")  # fmt: skip
    settings = settings or {}
    trials = []
    for task in tasks:
        for algo in algos:
            agent = agent_spec(algo)  # raises for an unknown name, listing the registered ones
            spec = task_of(Trial(task, algo, 0).env_id)
            if spec is not None and not agent.acts_in(spec.continuous):
                continue
            changes = dict(overrides)
            for name, value in settings.get(algo, {}).items():  # a group's settings join the group's
                both = isinstance(value, dict) and isinstance(changes.get(name), dict)
                changes[name] = {**changes[name], **value} if both else value
            trials.extend(Trial(task, algo, seed, preset, changes, variant) for seed in seeds)
    if not trials:
        raise ValueError(f"no algorithm of {list(algos)} acts in the tasks {list(tasks)}")
    for trial in trials:
        trial.config()  # bad settings fail here, before any trial starts
    return trials


def run_trial(trial: Trial, root: str | Path, progress: bool = False) -> Path:
    """Train the trial in ``root/<name>``, resuming what is there.

    Raises:
        ValueError: the folder holds a run with other settings (more epochs
            are allowed: the run is extended).
    """
    run_dir = Path(root) / trial.name
    wanted = trial.config()
    if (run_dir / "config.json").exists():
        differing = setting_differences(run_dir, wanted)
        if differing:
            raise ValueError(f"{run_dir} holds a run with other settings ({', '.join(differing)}); "
                             "use another --root")  # fmt: skip
        extend = wanted.epochs > read_config(run_dir).epochs  # never shortened: a longer run is kept
        return train(wanted if extend else None, run_dir=run_dir, resume=True, progress=progress)
    return train(wanted, run_dir=run_dir, progress=progress)


def ray_available() -> bool:
    return importlib.util.find_spec("ray") is not None


RECORD_FILES = (
    "config.json",
    "world.json",
    "progress.csv",
    "typing.json",
    "result.json",
    "tuning.json",
    "touch.json",
    "transfer.json",
    "init.json",
)
"""What a run's archived record holds: everything a report reads, no checkpoint or replay."""


def record_differences(record: Path, config) -> list[str]:
    """The settings, machine settings aside, in which an archived record differs from ``config``."""
    return differences(read_config(record), config, ignore=MACHINE_SETTINGS)


def archive_run(run_dir: str | Path, into: str | Path) -> Path:
    """Copy a run's record to ``into/<run folder name>`` (replacing an older copy), after evaluating
    its typing on its last checkpoint where that is not done yet; returns the copy's folder."""
    from tactile_braille.evaluation.runs import evaluate_typing

    run_dir = Path(run_dir)
    config = read_config(run_dir)  # refuses a folder that holds no run
    target = Path(into) / run_dir.name
    epochs = len(read_progress(run_dir))
    if (target / "config.json").exists():  # never lose a record: refuse another run's, or a longer one
        other = record_differences(target, config)
        if other:
            raise ValueError(f"{target} holds the record of a run with other settings ({', '.join(other)})")
        if len(read_progress(target)) > epochs:
            raise ValueError(f"{target} holds a longer record ({len(read_progress(target))} epochs) than "
                             f"{run_dir} ({epochs}); archive elsewhere or remove it")  # fmt: skip
    typing = run_dir / "typing.json"
    evaluated = json.loads(typing.read_text()) if typing.exists() else {}
    stale = evaluated.get("checkpoint_epoch") != epochs - 1 or "released_protocol" not in evaluated
    if stale and (run_dir / "checkpoint.pt").exists():
        evaluate_typing(run_dir)
    target.mkdir(parents=True, exist_ok=True)
    for name in RECORD_FILES:
        if (run_dir / name).exists():
            with atomic_path(target / name) as temporary:
                shutil.copyfile(run_dir / name, temporary)
        else:
            (target / name).unlink(missing_ok=True)
    return target


def archived(trial: Trial, archive: str | Path | None) -> Path | None:
    """The trial's archived record if it is complete (every epoch, typing evaluated at the last) and
    was made with the trial's settings; else None."""
    if archive is None:
        return None
    record = Path(archive) / trial.name
    if not (record / "config.json").exists():
        return None
    wanted = trial.config()
    other = record_differences(record, wanted)
    if other:  # refused before any work, not when the trial's record is written
        raise ValueError(f"{record} holds the record of a run with other settings ({', '.join(other)}); "
                         "use another --archive")  # fmt: skip
    if not (record / "typing.json").exists():
        return None
    epochs = len(read_progress(record))
    typed = json.loads((record / "typing.json").read_text()).get("checkpoint_epoch")
    return record if epochs >= wanted.epochs and typed == epochs - 1 else None


def sweep(
    trials: Sequence[Trial],
    root: str | Path,
    use_ray: bool | None = None,
    address: str | None = None,
    cpus_per_trial: float = 2,
    max_failures: int = 2,
    progress: bool = True,
    jobs: int = 1,
    archive: str | Path | None = None,
) -> list[Path]:
    """Run the trials; returns their run folders (in the order given), or their archived records
    where those were complete before the sweep (:func:`archived`: such trials are not run).

    ``use_ray=None`` uses Ray when it is installed; without it ``jobs`` trials run at a time, each in
    its own process. ``archive``: a folder that receives each finished trial's record.
    """
    if jobs < 1:
        raise ValueError(f"jobs must be at least 1, got {jobs}")
    for trial in trials:
        trial.config()  # bad settings fail here, before any trial starts
    if use_ray and not ray_available():
        raise ValueError("--ray yes needs Ray: pip install 'tactile_braille[sweep]' (or --ray no)")
    root = Path(root).resolve()
    root.mkdir(parents=True, exist_ok=True)
    done = {trial.name: archived(trial, archive) for trial in trials}
    pending = [trial for trial in trials if done[trial.name] is None]
    if progress and len(pending) < len(trials):
        print(f"{len(trials) - len(pending)} trials archived complete in {archive}: not run again")
    if use_ray is None:
        use_ray = ray_available()
    if use_ray and pending:
        try:
            _sweep_on_ray(pending, root, address, cpus_per_trial, max_failures)
        finally:  # what finished is archived, even when another trial failed
            for trial in pending if archive is not None else ():
                if (root / trial.name / "config.json").exists():
                    archive_run(root / trial.name, archive)
    elif jobs > 1 and len(pending) > 1:
        context = multiprocessing.get_context("spawn")  # no torch state shared with the parent
        with ProcessPoolExecutor(min(jobs, len(pending)), mp_context=context) as pool:
            futures = [pool.submit(run_with_retries, t, root, max_failures, False, archive) for t in pending]
            done_futures, _ = wait(futures, return_when=FIRST_EXCEPTION)
            failed = [future for future in done_futures if future.exception() is not None]
            if failed:  # the trials not started are dropped; those running finish and are kept
                pool.shutdown(cancel_futures=True)
                raise failed[0].exception()
    else:
        for number, trial in enumerate(pending, start=1):
            if progress:
                print(f"[{number}/{len(pending)}] {trial.name}")
            run_with_retries(trial, root, max_failures, progress, archive)
    return [done[trial.name] or root / trial.name for trial in trials]


def run_with_retries(
    trial: Trial, root: Path, max_failures: int, progress: bool, archive: str | Path | None = None
) -> Path:
    """Run a trial, retrying a failure (each retry resumes from the last checkpoint); archive its
    record when it has finished, if there is an archive."""
    for attempt in range(max_failures + 1):
        try:
            run_dir = run_trial(trial, root, progress=progress)
            if archive is not None:
                archive_run(run_dir, archive)
            return run_dir
        except ValueError:  # wrong settings: a retry would fail the same way
            raise
        except Exception as error:  # a retry resumes from the last checkpoint
            if attempt == max_failures:
                raise RuntimeError(f"trial {trial.name} failed {attempt + 1} times") from error
            print(f"trial {trial.name} failed ({error!r}); retrying from its last checkpoint")
    raise AssertionError("unreachable")


def _sweep_on_ray(trials, root: Path, address, cpus_per_trial: float, max_failures: int) -> None:
    import ray
    from ray import tune

    def trainable(space: dict) -> None:
        import torch

        fields = dict(space["trial"])
        # One torch thread per CPU the trial was given, unless the trial says otherwise.
        fields["overrides"] = {"threads": max(int(cpus_per_trial), 1), **fields["overrides"]}
        trial = Trial(**fields)
        torch.set_num_threads(fields["overrides"]["threads"])
        run_dir = run_trial(trial, space["root"])
        from tactile_braille.agents.run import read_progress

        rows = read_progress(run_dir)
        tune.report({"test_return": rows[-1]["test/episodic_return"], "epochs": len(rows)})

    started = False
    if not ray.is_initialized():
        ray.init(address=address, include_dashboard=False, log_to_driver=False, configure_logging=False)
        started = True
    try:
        space = {"trial": tune.grid_search([dataclasses.asdict(t) for t in trials]), "root": str(root)}
        tuner = tune.Tuner(
            tune.with_resources(trainable, {"cpu": cpus_per_trial}),
            param_space=space,
            run_config=tune.RunConfig(
                name="tactile_braille_sweep",
                storage_path=str(root / "_ray"),
                failure_config=tune.FailureConfig(max_failures=max_failures),
                verbose=0,
            ),
        )
        results = tuner.fit()
        failed = [result for result in results if result.error is not None]
        if failed:
            raise RuntimeError(f"{len(failed)} trials failed on Ray; first error: {failed[0].error}")
    finally:
        if started:
            ray.shutdown()
