"""The benchmark's tuning protocol, for any method (docs/benchmark.md#the-tuning-protocol).

1. **Search** (:func:`search`): an Optuna study (TPE sampler; median pruning on the typing score at a
   third and two thirds of a trial's budget) over a stated search space, each trial trained on one
   tuning seed or on several in turn (100 unless told; seeds 100-199 are never reported) and scored
   by typing accuracy, then by fewer steps, under the paper's protocol (the mean over its seeds). The
   untuned settings are always among the trials. The study lives in a SQLite file whose trials send
   a heartbeat, so a killed search resumes where it stopped (its unfinished trial is failed and run
   again), and two processes can search one study side by side. After each trial the search's record
   (:func:`summary`) is written beside the study as JSON.
2. **Final runs**: the best trial's settings on fresh seeds; each results file records the search
   under ``tuning`` (:func:`finished_search` reads it back from the study, or from the record alone
   on a machine without the study).

A method plugs in with the function that trains and scores one trial: Stable-Baselines3's agents in
:mod:`tactile_braille.baselines.sb3`, this project's in :mod:`tactile_braille.tuning`. Optuna
is imported only when a search runs (``pip install tactile_braille[tune]``). A search space's parts,
:class:`Range` and ``Choice``, are defined with the settings (:mod:`tactile_braille.agents.config`),
whose classes name their agent's space.
"""

from __future__ import annotations

import json
import warnings
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from tactile_braille._io import atomic_path
from tactile_braille.agents.config import Choice as Choice  # a space's parts live with the settings
from tactile_braille.agents.config import Range, Space

if TYPE_CHECKING:
    from tactile_braille.evaluation.scoring import TypingReport

TUNING_SEEDS = tuple(range(100, 200))
"""Seeds a search may train on; results are reported on others."""

FINISHED = ("COMPLETE", "PRUNED")
"""The trial states a search counts (a failed trial, its process killed, is run again)."""

Check = Callable[[int, "TypingReport"], None]
"""Called by a trial with its training steps so far and a typing report at each of its checks; raises
``optuna.TrialPruned`` where the trial should stop."""


def objective(report: TypingReport) -> float:
    """What a search maximises: the leaderboard's per-seed :func:`typing_score` (accuracy, then fewer
    steps)."""
    from tactile_braille.evaluation.leaderboard import typing_score

    return typing_score(report.accuracy, report.total_steps, report.keys_asked)


def check_tuning_seed(seed: int) -> None:
    """Refuse a search seed that is not a tuning seed."""
    if seed not in TUNING_SEEDS:
        raise ValueError(
            f"a search trains on tuning seeds ({TUNING_SEEDS[0]}-{TUNING_SEEDS[-1]}), got {seed}"
        )


def check_reported_seeds(seeds) -> None:
    """Refuse final-run seeds among the tuning seeds."""
    clash = sorted(set(seeds) & set(TUNING_SEEDS))
    if clash:
        raise ValueError(f"seeds {clash} are tuning seeds: report on others")


def check_points(steps: int) -> tuple[int, int]:
    """The training steps after which a trial of ``steps`` reports its typing (pruning's checks)."""
    return steps // 3, 2 * steps // 3


def check_untuned(space: Space, untuned: dict[str, Any]) -> None:
    """Refuse untuned settings that the search space cannot hold (a search always tries them)."""
    problems = [f"{name}: none given" for name in space if name not in untuned]
    for name, dim in space.items():
        value = untuned.get(name)
        if name not in untuned:
            continue
        if isinstance(dim, Range) and not (isinstance(value, int | float) and dim.low <= value <= dim.high):
            problems.append(f"{name}: {value!r} is outside [{dim.low}, {dim.high}]")
        elif not isinstance(dim, Range) and value not in dim:
            problems.append(f"{name}: {value!r} is none of {list(dim)}")
    if problems:
        raise ValueError("the untuned settings are not in the search space (" + "; ".join(problems) + ")")


def space_record(space: Space) -> dict:
    """A search space as its record writes it."""
    return {name: {"range": [dim.low, dim.high], "log": dim.log} if isinstance(dim, Range)
            else {"choice": list(dim)} for name, dim in space.items()}  # fmt: skip


def open_study(path: Path, name: str, create: bool):
    """The study ``name`` in the SQLite file ``path``: its trials send a heartbeat, so that a trial whose
    process was killed is failed (and not counted) when any process next searches."""
    optuna = _optuna()
    if not create and not Path(path).exists():
        raise FileNotFoundError(f"no study at {path}: run the search first")
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    with warnings.catch_warnings():  # Optuna marks the heartbeat experimental
        warnings.simplefilter("ignore", optuna.exceptions.ExperimentalWarning)
        storage = optuna.storages.RDBStorage(f"sqlite:///{path}", heartbeat_interval=30, grace_period=120)
    return optuna.create_study(
        study_name=name, storage=storage, direction="maximize", load_if_exists=True,
        sampler=optuna.samplers.TPESampler(), pruner=optuna.pruners.MedianPruner(n_startup_trials=4),
    )  # fmt: skip


def _optuna():
    try:
        import optuna
    except ImportError as error:
        raise ImportError(
            "a search needs Optuna: pip install 'tactile_braille[tune]' (or optuna>=4.0)"
        ) from error
    return optuna


def _fail_stale(study) -> None:
    """Fail the trials whose process stopped sending its heartbeat (Optuna marks the call experimental)."""
    optuna = _optuna()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", optuna.exceptions.ExperimentalWarning)
        optuna.storages.fail_stale_trials(study)


def _finished(study) -> list:
    return [t for t in study.trials if t.state.name in FINISHED]


def _suggest(trial, space: Space) -> dict:
    return {name: trial.suggest_float(name, dim.low, dim.high, log=dim.log) if isinstance(dim, Range)
            else trial.suggest_categorical(name, list(dim)) for name, dim in space.items()}  # fmt: skip


def search(
    study_path: Path,
    identity: dict[str, Any],
    space: Space,
    untuned: dict[str, Any],
    trials: int,
    seeds: Sequence[int],
    steps: int,
    train_and_score: Callable[[dict, int, Check], tuple[TypingReport, float]],
) -> dict:
    """Run the search until the study at ``study_path`` holds ``trials`` finished or pruned trials,
    counting those other processes are running (the module docstring); returns :func:`summary`, also
    written beside the study.

    Args:
        study_path: the study's SQLite file (``.db``); the record goes beside it (``.json``).
        identity: what is searched (``task``, ``algo`` and what else names the method), at the head of
            the record. The study's name is the file's (``TASK__ALGO.db``: ``TASK__ALGO``).
        space: the search space; ``untuned``: the settings before any search (a value for each of the
            space's names), always among the trials.
        trials: trials to finish in all.
        seeds: the tuning seeds every trial trains on, one after the other (its score: the mean of
            theirs); ``steps``: each training run's steps. A study searches with one set of seeds and
            one budget: another is refused.
        train_and_score: trains ``settings`` (the space's names) on one seed and returns its typing
            report and minutes of training; it calls ``check(steps_done, report)`` at
            :func:`check_points` where it can. A trial may be pruned at those checks and after each
            seed but the last (its steps counted on from the seeds before).
    """
    optuna = _optuna()
    seeds = [int(seed) for seed in seeds]
    if not seeds or len(set(seeds)) != len(seeds):
        raise ValueError(f"a search needs one or more distinct tuning seeds, got {seeds}")
    for seed in seeds:
        check_tuning_seed(seed)
    check_untuned(space, untuned)
    study = open_study(study_path, Path(study_path).stem, create=True)
    _claim(study, study_path, seeds, steps, space, untuned)
    first = {name: untuned[name] for name in space}
    queued = [t.params or t.system_attrs.get("fixed_params") for t in study.trials if t.state.name != "FAIL"]
    if first not in queued:  # the untuned settings are always among the trials
        study.enqueue_trial(first)

    def run_trial(trial) -> float:
        settings = _suggest(trial, space)
        trial.set_user_attr("seed", seeds[0])
        trial.set_user_attr("steps", steps)
        reports, minutes = [], 0.0
        for index, seed in enumerate(seeds):

            def check(done: int, report: TypingReport, before: int = index * steps) -> None:
                trial.report(objective(report), before + done)
                if trial.should_prune():
                    raise optuna.TrialPruned()

            report, taken = train_and_score(settings, seed, check)
            reports.append(report)
            minutes += taken
            if index + 1 < len(seeds):
                check(steps, report)
        trial.set_user_attr("accuracy", float(np.mean([r.accuracy for r in reports])))
        trial.set_user_attr("total_steps", float(np.mean([r.total_steps for r in reports])))
        if len(seeds) > 1:
            trial.set_user_attr("per_seed", [[r.accuracy, r.total_steps] for r in reports])
        trial.set_user_attr("minutes", round(minutes, 2))
        return float(np.mean([objective(r) for r in reports]))

    while True:
        _fail_stale(study)  # a killed process's trial is run again
        if len(_finished(study)) + sum(t.state.name == "RUNNING" for t in study.trials) >= trials:
            break
        study.optimize(run_trial, n_trials=1)
        _write_record(study_path, summary(study, identity, space, untuned))
    result = summary(study, identity, space, untuned)
    _write_record(study_path, result)
    return result


def _claim(study, study_path: Path, seeds: list[int], steps: int, space: Space, untuned: dict) -> None:
    """Record the study's seeds, budget, space and untuned settings, or refuse others than those it
    recorded."""
    if "seed" in study.user_attrs and "seeds" not in study.user_attrs:  # a one-seed study's record
        study.set_user_attr("seeds", [study.user_attrs["seed"]])
    searched = json.loads(json.dumps(space_record(space), default=json_value))  # as the study stores it
    untuned = json.loads(json.dumps(untuned, default=json_value))
    claims = (
        ("seeds", seeds),
        ("seed", seeds[0]),
        ("steps", steps),
        ("space", searched),
        ("defaults", untuned),
    )
    for name, value in claims:
        recorded = study.user_attrs.get(name)
        if recorded is None:
            study.set_user_attr(name, value)
        elif recorded != value:
            raise ValueError(
                f"{study_path} searches with {name} {recorded}, not {value}: one study, one protocol"
            )


def summary(study, identity: dict[str, Any], space: Space, untuned: dict[str, Any]) -> dict:
    """The search as a results file records it: what was searched, the space and the untuned
    settings (those the study recorded; ``space`` and ``untuned`` for a study that recorded none),
    the budget, the tuning seeds (``seed``: the first), its finished trials (the count, and each), the
    best. With several seeds a trial's accuracy and steps are their means, and ``per_seed`` lists each
    seed's (accuracy, steps)."""
    finished = _finished(study)
    complete = [t for t in finished if t.state.name == "COMPLETE"]
    best = max(complete, key=lambda t: t.value) if complete else None
    seeds = study.user_attrs.get("seeds") or [study.user_attrs.get("seed")]
    return {
        **identity,
        "search": "optuna TPE, median pruning",
        "space": study.user_attrs.get("space") or space_record(space),  # what it searched
        "defaults": study.user_attrs.get("defaults") or untuned,  # what its first trial ran
        "objective": "typing accuracy, then fewer steps"
        + (", the mean over the tuning seeds" if len(seeds) > 1 else ""),
        "seed": seeds[0],
        "seeds": seeds,
        "steps": study.user_attrs.get("steps"),
        "trials": len(finished),
        "trial_log": [
            {"number": t.number, "state": t.state.name, "params": t.params, "value": t.value, **t.user_attrs}
            for t in finished
        ],
        "best": None if best is None else {"number": best.number, "params": best.params, **best.user_attrs},
    }


def _write_record(study_path: Path, content: dict) -> None:
    with atomic_path(Path(study_path).with_suffix(".json")) as temporary:
        temporary.write_text(json.dumps(content, indent=2, default=json_value) + "\n")


def json_value(value):
    """A value JSON does not take (a numpy scalar: its Python value; anything else: its text)."""
    return value.item() if isinstance(value, np.generic) else str(value)


def _described(identity: dict[str, Any]) -> str:
    preset = f" from the `{identity['preset']}` preset" if identity.get("preset") else ""
    return f"{identity.get('algo')}{preset} on {identity.get('task')}"


def finished_search(study_path: Path, identity: dict[str, Any], space: Space, untuned: dict) -> dict:
    """A finished search (:func:`summary`): from its study at ``study_path``, whose trials must all have
    finished, or else from the record written beside it (the ``.json``), which may travel without the
    study. A record of another search (its ``identity`` differs) is refused, as is a search with no
    complete trial."""
    path, record = Path(study_path), Path(study_path).with_suffix(".json")
    if path.exists():
        study = open_study(path, path.stem, create=False)
        _fail_stale(study)  # trials whose process stopped sending its heartbeat
        going = [t.number for t in study.trials if t.state.name in ("RUNNING", "WAITING")]
        if going:
            raise ValueError(f"{path}: trials {going} are still running or queued; let the search finish")
        tuning, source = summary(study, identity, space, untuned), path
        _write_record(path, tuning)  # the record beside it says the same
    elif record.exists():
        tuning, source = json.loads(record.read_text()), record
        found = {name: tuning.get(name) for name in identity}
        if found != identity or not {"best", "steps", "trials"} <= tuning.keys():
            searched = _described(identity)
            raise ValueError(f"{record} is no record of a search of {searched} (it names {found})")
    else:
        raise FileNotFoundError(f"no study at {path} and no record of one at {record}: run the search first")
    if tuning["best"] is None:
        raise ValueError(f"{source} holds no finished trial yet")
    return tuning
