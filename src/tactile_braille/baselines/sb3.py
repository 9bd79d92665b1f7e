"""Stable-Baselines3 with Hindsight Experience Replay, tuned by the benchmark's protocol.

The agents are SB3's own (DQN on the discrete tasks; SAC and TD3 on the
continuous ones) and SB3-Contrib's (QR-DQN; TQC), with SB3's
``HerReplayBuffer``, on the environment exactly as registered (the ``tactile``
track), scored by
:func:`~tactile_braille.evaluation.evaluate_policy`. The protocol every method
on the leaderboard gets (docs/benchmark.md#the-tuning-protocol):

1. **Search** (``tune``): an Optuna study (TPE; median pruning on the typing
   score at a third and two thirds of the budget) over the algorithm's
   :data:`SEARCH_SPACES`, each trial trained for the task's official budget
   (or a stated shorter one, ``--steps``, where a trial at the budget costs
   too much) on one tuning seed (100 unless told; seeds 100-199 are never
   reported) and scored by typing accuracy, then by steps. The untuned
   :data:`DEFAULTS` are always among the trials. The study lives in a SQLite
   file whose trials send a heartbeat, so a killed search resumes where it
   stopped (its unfinished trial is failed and run again), and two processes
   can search one study side by side.
2. **Final runs** (``run``): the best trial's settings, trained on fresh seeds
   at the task's official budget; each results file records the search (space,
   trials, tuning seed, the trials' budget, chosen settings) under ``tuning``.
   Each seed checkpoints as it trains, and a stopped seed goes on from its
   latest checkpoint.

    python -m tactile_braille.baselines.sb3 tune DiscreteArrows-v0 dqn --trials 16 --study runs/tune
    python -m tactile_braille.baselines.sb3 run DiscreteArrows-v0 dqn --study runs/tune --seeds 0 1 2 3 4 \\
        --into results/leaderboard/sb3-tuned
"""

from __future__ import annotations

import argparse
import json
import shutil
import time
import warnings
from dataclasses import dataclass
from pathlib import Path

import gymnasium as gym

from tactile_braille._io import atomic_path
from tactile_braille._tasks import REGISTERED_TASKS, RegisteredTask, registered_task
from tactile_braille.evaluation.results import make_result, write_result
from tactile_braille.evaluation.scoring import TypingReport, evaluate_policy
from tactile_braille.search import (
    TUNING_SEEDS,
    Choice,
    Range,
    check_points,
    check_reported_seeds,
    check_tuning_seed,
    finished_search,
    json_value,
    search,
)

DEFAULTS: dict[str, dict] = {
    "dqn": {"learning_rate": 1e-4, "gamma": 0.99, "batch_size": 32, "train_freq": 1, "gradient_steps": 1,
            "learning_starts": 1_000, "target_update_interval": 500, "exploration_fraction": 0.3,
            "exploration_final_eps": 0.05, "goal_selection_strategy": "future", "n_sampled_goal": 4},
    "sac": {"learning_rate": 3e-4, "gamma": 0.99, "batch_size": 64, "learning_starts": 1_000, "tau": 0.005,
            "ent_coef": "auto", "goal_selection_strategy": "future", "n_sampled_goal": 4},
    "td3": {"learning_rate": 1e-3, "gamma": 0.99, "batch_size": 64, "learning_starts": 1_000, "tau": 0.005,
            "goal_selection_strategy": "future", "n_sampled_goal": 4},
    "qrdqn": {"learning_rate": 5e-5, "gamma": 0.99, "batch_size": 32, "train_freq": 1, "gradient_steps": 1,
              "learning_starts": 1_000, "target_update_interval": 500, "exploration_fraction": 0.3,
              "exploration_final_eps": 0.05, "goal_selection_strategy": "future", "n_sampled_goal": 4},
    "tqc": {"learning_rate": 3e-4, "gamma": 0.99, "batch_size": 64, "learning_starts": 1_000, "tau": 0.005,
            "ent_coef": "auto", "top_quantiles_to_drop_per_net": 2, "goal_selection_strategy": "future",
            "n_sampled_goal": 4},
}  # fmt: skip
"""Each algorithm's settings before any search: the library's defaults, but for a learning start, a
target network, an exploration decay and an update every step that fit these budgets (DQN, QR-DQN)
and batches of 64 (SAC, TD3, TQC), as the untuned rows of the leaderboard ran
(``examples/sb3_her.py``). The image network is shared by the actor and critics
(``share_features_extractor``) in SAC, TD3 and TQC. SB3-Contrib's CrossQ takes vector observations
only (its one policy is ``MlpPolicy``), not the tasks' images with goals, so it is not among them."""


@dataclass(frozen=True)
class Algorithm:
    """One algorithm of a library: where its class lives, the actions it takes, its leaderboard label."""

    package: str  # the distribution: "stable-baselines3" or "sb3-contrib"
    module: str  # its import name
    name: str  # the class
    actions: str  # "discrete" or "continuous"
    label: str

    def model_class(self):
        import importlib

        return getattr(importlib.import_module(self.module), self.name)


_SB3, _CONTRIB = ("stable-baselines3", "stable_baselines3"), ("sb3-contrib", "sb3_contrib")
ALGORITHMS: dict[str, Algorithm] = {
    "dqn": Algorithm(*_SB3, "DQN", "discrete", "SB3 DQN + HER"),
    "sac": Algorithm(*_SB3, "SAC", "continuous", "SB3 SAC + HER"),
    "td3": Algorithm(*_SB3, "TD3", "continuous", "SB3 TD3 + HER"),
    "qrdqn": Algorithm(*_CONTRIB, "QRDQN", "discrete", "SB3-Contrib QR-DQN + HER"),
    "tqc": Algorithm(*_CONTRIB, "TQC", "continuous", "SB3-Contrib TQC + HER"),
}
"""The algorithms the module runs, by the name the command line takes."""

_HER = {
    "goal_selection_strategy": Choice(("future", "final", "episode")),
    "n_sampled_goal": Choice((2, 4, 8)),
}
_ENTROPY = Choice(("auto", "auto_0.1", "auto_0.01"))  # the entropy weight's start (SB3: "auto" starts at 1)
SEARCH_SPACES: dict[str, dict[str, Range | Choice]] = {
    "dqn": {"learning_rate": Range(1e-4, 1e-3, log=True), "gamma": Choice((0.9, 0.95, 0.98, 0.99)),
            "batch_size": Choice((32, 64)), "train_freq": Choice((1, 4)), "gradient_steps": Choice((1, 2)),
            "learning_starts": Choice((200, 500, 1_000)),
            "target_update_interval": Choice((100, 250, 500, 1_000)), "exploration_fraction": Range(0.1, 0.5),
            "exploration_final_eps": Choice((0.02, 0.05, 0.1)), **_HER},
    "sac": {"learning_rate": Range(1e-4, 1e-3, log=True), "gamma": Choice((0.9, 0.95, 0.98, 0.99)),
            "batch_size": Choice((64, 128)), "learning_starts": Choice((200, 500, 1_000)),
            "tau": Choice((0.005, 0.01, 0.02)), "ent_coef": _ENTROPY, **_HER},
    "td3": {"learning_rate": Range(1e-4, 1e-3, log=True), "gamma": Choice((0.9, 0.95, 0.98, 0.99)),
            "batch_size": Choice((64, 128)), "learning_starts": Choice((200, 500, 1_000)),
            "tau": Choice((0.005, 0.01, 0.02)), **_HER},
    "qrdqn": {"learning_rate": Range(5e-5, 1e-3, log=True), "gamma": Choice((0.9, 0.95, 0.98, 0.99)),
              "batch_size": Choice((32, 64)), "train_freq": Choice((1, 4)), "gradient_steps": Choice((1, 2)),
              "learning_starts": Choice((200, 500, 1_000)),
              "target_update_interval": Choice((100, 250, 500, 1_000)),
              "exploration_fraction": Range(0.1, 0.5), "exploration_final_eps": Choice((0.02, 0.05, 0.1)),
              **_HER},
    "tqc": {"learning_rate": Range(1e-4, 1e-3, log=True), "gamma": Choice((0.9, 0.95, 0.98, 0.99)),
            "batch_size": Choice((64, 128)), "learning_starts": Choice((200, 500, 1_000)),
            "tau": Choice((0.005, 0.01, 0.02)), "ent_coef": _ENTROPY,
            "top_quantiles_to_drop_per_net": Choice((0, 2, 5)), **_HER},
}  # fmt: skip
"""What a search may change, per algorithm (the HER goal strategy and count for all; for SAC and TQC,
where their learnt entropy weight starts)."""


def _registered(task: str) -> RegisteredTask:
    registered = registered_task(task)
    if registered is None or registered.budget_steps is None:
        raise ValueError(f"{task!r} is no registered task with an official budget; choose one of "
                         f"{[t.name for t in REGISTERED_TASKS]}")  # fmt: skip
    return registered


def official_budget(task: str) -> int:
    """The task's official training budget in environment steps (:mod:`tactile_braille._tasks`)."""
    return _registered(task).budget_steps


def check_algo(task: str, algo: str) -> None:
    """Refuse an algorithm this module does not run, or one that cannot act in the task's actions."""
    if algo not in ALGORITHMS:
        raise ValueError(f"algo must be one of {sorted(ALGORITHMS)}, got {algo!r}")
    kind = "continuous" if _registered(task).continuous else "discrete"
    takes = ALGORITHMS[algo].actions
    if takes != kind:
        able = sorted(name for name, a in ALGORITHMS.items() if a.actions == kind)
        raise ValueError(f"{algo} takes {takes} actions; {task}'s are {kind}: use one of {able}")


def _env(task: str, dataset=None):
    return gym.make(f"tactile_braille/{task}", **({"dataset": str(dataset)} if dataset else {}))


def make_model(task: str, algo: str, settings: dict, steps: int, seed: int, dataset=None, device="cpu"):
    """An SB3 (or SB3-Contrib) model of ``algo`` with ``settings`` (:data:`DEFAULTS`' names) on ``task``,
    its replay holding the whole run, its networks on ``device``."""
    from stable_baselines3 import HerReplayBuffer

    check_algo(task, algo)
    settings = {**DEFAULTS[algo], **settings}
    her = {name: settings.pop(name) for name in ("goal_selection_strategy", "n_sampled_goal")}
    settings["learning_starts"] = min(settings["learning_starts"], steps)
    if ALGORITHMS[algo].actions == "continuous":
        settings["policy_kwargs"] = {"share_features_extractor": True}
    model_class = ALGORITHMS[algo].model_class()
    return model_class(
        "MultiInputPolicy", _env(task, dataset), replay_buffer_class=HerReplayBuffer,
        replay_buffer_kwargs=her, buffer_size=max(steps, 1), seed=seed, device=device, verbose=0, **settings,
    )  # fmt: skip


def score(model, task: str, dataset=None) -> TypingReport:
    """The model's deterministic policy typing the paper's sequences (the benchmark's protocol)."""
    return evaluate_policy(lambda observation: model.predict(observation, deterministic=True)[0], task,
                           dataset=dataset)  # fmt: skip


CHECKPOINT_EVERY = 2_500
"""Environment steps between a final run's checkpoints (a tenth of the continuous tasks' budget)."""


def train(task: str, algo: str, settings: dict, steps: int, seed: int, dataset=None, checks=(), check=None,
          device="cpu", checkpoints: Path | None = None, every: int = CHECKPOINT_EVERY):  # fmt: skip
    """Train for ``steps`` environment steps on ``device`` (one CPU thread); ``check(steps_so_far,
    report)`` is called with a typing report after each step count in ``checks`` (a search's pruning).

    With ``checkpoints`` (a folder), the model, its optimisers and its replay are saved there every
    ``every`` steps, and a call that finds a checkpoint of the same run (task, algorithm, settings,
    budget, seed) goes on from it: a stopped run loses at most ``every`` steps. A resumed run is not
    bit-identical to an unbroken one (the random generators restart from ``seed`` and the steps done),
    and its replay's episode in progress is closed where it stopped. Returns (model, seconds of training
    over all its calls)."""
    import torch
    from stable_baselines3.common.callbacks import BaseCallback

    torch.set_num_threads(1)
    run = {"task": task, "algo": algo, "settings": settings, "steps": steps, "seed": seed}
    run = json.loads(json.dumps(run, default=json_value))  # as its claim on a checkpoint folder reads back
    resumed = _resume(checkpoints, run, dataset, device) if checkpoints is not None else None
    model, done, seconds_before = resumed or (make_model(task, algo, settings, steps, seed, dataset, device),
                                              0, 0.0)  # fmt: skip
    start = time.perf_counter()

    class Steps(BaseCallback):
        def _on_step(self) -> bool:
            if self.num_timesteps in checks and check is not None:
                check(self.num_timesteps, score(self.model, task, dataset))
            if checkpoints is not None and self.num_timesteps % every == 0 and self.num_timesteps < steps:
                _save_checkpoint(self.model, checkpoints, seconds_before + time.perf_counter() - start)
            return True

    model.learn(steps - done, callback=Steps(), reset_num_timesteps=done == 0)
    return model, seconds_before + time.perf_counter() - start


def _save_checkpoint(model, folder: Path, seconds: float) -> None:
    """Save the model and its replay as ``step-N`` in ``folder``, whole or not at all (written under
    another name, then renamed), and remove the older ones."""
    final = folder / f"step-{model.num_timesteps}"
    partial = folder / f".{final.name}.partial"
    shutil.rmtree(partial, ignore_errors=True)
    partial.mkdir(parents=True)
    model.save(partial / "model.zip")
    model.save_replay_buffer(partial / "replay.pkl")
    (partial / "progress.json").write_text(json.dumps({"steps": model.num_timesteps, "seconds": seconds}))
    partial.rename(final)
    for older in folder.glob("step-*"):
        if older != final:
            shutil.rmtree(older)


def _resume(folder: Path, run: dict, dataset, device: str):
    """(model, steps done, seconds so far) from the latest checkpoint in ``folder``, or None where there is
    none; the folder is claimed for ``run``, and one of another run is refused before anything is
    loaded."""
    folder.mkdir(parents=True, exist_ok=True)
    claim = folder / "run.json"
    if claim.exists():
        theirs = json.loads(claim.read_text())
        if theirs != run:
            differ = sorted(name for name in run if theirs.get(name) != run[name])
            raise ValueError(f"{folder} holds checkpoints of another run (its {differ} differ): "
                             f"remove it or checkpoint elsewhere")  # fmt: skip
    else:
        with atomic_path(claim) as path:
            path.write_text(json.dumps(run, indent=1))
    for unfinished in folder.glob(".step-*.partial"):  # a save the stop cut short
        shutil.rmtree(unfinished)
    saved = sorted(folder.glob("step-*"), key=lambda p: int(p.name.removeprefix("step-")))
    if not saved:
        return None
    latest = saved[-1]
    progress = json.loads((latest / "progress.json").read_text())
    model = ALGORITHMS[run["algo"]].model_class().load(latest / "model.zip", env=_env(run["task"], dataset),
                                                       device=device)  # fmt: skip
    with warnings.catch_warnings():  # SB3 warns that the episode in progress is closed: it is, on purpose
        warnings.filterwarnings("ignore", "The last trajectory in the replay buffer will be truncated")
        model.load_replay_buffer(latest / "replay.pkl")
    model.set_random_seed(run["seed"] + progress["steps"])
    model._last_obs = None  # the environment is new: the next learn starts an episode
    return model, progress["steps"], progress["seconds"]


def _identity(task: str, algo: str) -> dict:
    return {"library": ALGORITHMS[algo].package, "algo": algo, "task": task}


def tune(task: str, algo: str, trials: int, study_dir: Path, seed: int = TUNING_SEEDS[0], steps=None,
         dataset=None, device: str = "cpu") -> dict:  # fmt: skip
    """Run the search (:func:`tactile_braille.search.search`) until the study ``TASK__ALGO.db`` in
    ``study_dir`` holds ``trials`` finished or pruned trials; returns its record, also written beside
    the study. Each trial trains for ``steps`` (the official budget unless told) on ``device``."""
    check_algo(task, algo)
    check_tuning_seed(seed)
    steps = steps or official_budget(task)

    def train_and_score(settings: dict, seed: int, check) -> tuple[TypingReport, float]:
        model, seconds = train(task, algo, settings, steps, seed, dataset, check_points(steps), check, device)
        return score(model, task, dataset), seconds / 60

    return search(Path(study_dir) / f"{task}__{algo}.db", _identity(task, algo), SEARCH_SPACES[algo],
                  DEFAULTS[algo], trials, [seed], steps, train_and_score)  # fmt: skip


def _where(device: str) -> str:
    return "one CPU thread" if device == "cpu" else f"{device} and one CPU thread"


# ------------------------------------------------------------------ final runs
def search_record(study_dir: Path, task: str, algo: str) -> dict:
    """The finished search of ``algo`` on ``task`` (:func:`tactile_braille.search.finished_search`): from
    its study in ``study_dir``, or else from the record written beside it (``TASK__ALGO.json``)."""
    study = Path(study_dir) / f"{task}__{algo}.db"
    return finished_search(study, _identity(task, algo), SEARCH_SPACES[algo], DEFAULTS[algo])


def run_seeds(task: str, algo: str, study_dir: Path, seeds, into: Path, dataset=None, device: str = "cpu",
              steps=None, checkpoints: Path | None = None) -> list[Path]:  # fmt: skip
    """The best trial's settings trained on each of ``seeds`` (none a tuning seed) for ``steps`` (the
    task's official budget unless told), on ``device``; one results file each in ``into``. A file that
    exists is kept and a seed another process is training is left to it, so calls can go on side by side
    and after a stop. With ``checkpoints`` (a folder), each seed checkpoints in a subfolder of its own and
    a stopped seed goes on from its latest checkpoint (see :func:`train`); the subfolder is removed once
    the seed's results file is written. The search is read from its study in ``study_dir`` or, where
    there is none (on another machine), from the record ``tune`` writes beside it."""
    from tactile_braille._io import LockedError, exclusive_lock

    check_reported_seeds(seeds)
    steps = steps or official_budget(task)
    tuning = search_record(study_dir, task, algo)
    Path(into).mkdir(parents=True, exist_ok=True)
    written = []
    for seed in seeds:
        target = Path(into) / f"{task}__{algo}__{seed}.json"
        try:
            with exclusive_lock(Path(study_dir) / f".{target.name}.lock", f"the run of {target}"):
                if not target.exists():
                    saves = None if checkpoints is None else Path(checkpoints) / target.stem
                    model, seconds = train(task, algo, tuning["best"]["params"], steps, seed, dataset,
                                           device=device, checkpoints=saves)  # fmt: skip
                    result = make_result(
                        score(model, task, dataset), method=f"{ALGORITHMS[algo].label} (tuned)", seed=seed,
                        env_steps=steps,
                        notes=f"tactile_braille.baselines.sb3; {seconds / 60:.1f} min on {_where(device)}",
                        tuning=tuning,
                    )  # fmt: skip
                    write_result(result, target)
                    if saves is not None:
                        shutil.rmtree(saves)
        except LockedError:
            continue  # another process trains this seed
        written.append(target)
    return written


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(
        prog="python -m tactile_braille.baselines.sb3", description=__doc__.split("\n")[0]
    )
    commands = parser.add_subparsers(dest="command", required=True)
    for name in ("tune", "run"):
        command = commands.add_parser(name)
        command.add_argument("task", help="e.g. DiscreteArrows-v0")
        command.add_argument("algo", choices=sorted(ALGORITHMS))
        command.add_argument(
            "--study", type=Path, required=True,
            help="folder of the search's study (SQLite) and its record (JSON; `run` reads either)",
        )  # fmt: skip
        command.add_argument("--dataset", type=Path, help="the dataset backend's file (default: cached)")
        command.add_argument("--device", default="cpu", help="where the networks train: cpu (default), cuda")
    commands.choices["tune"].add_argument("--trials", type=int, required=True, help="trials to finish in all")
    commands.choices["tune"].add_argument("--seed", type=int, default=TUNING_SEEDS[0], help="the tuning seed")
    commands.choices["tune"].add_argument(
        "--steps", type=int, help="each trial's training steps (default: the official budget)"
    )
    commands.choices["run"].add_argument(
        "--steps", type=int, help="each seed's training steps (default: the official budget)"
    )
    commands.choices["run"].add_argument("--seeds", type=int, nargs="+", required=True)
    commands.choices["run"].add_argument(
        "--checkpoints", type=Path, default=Path("runs/checkpoints"),
        help=f"folder where each seed saves its model and replay every {CHECKPOINT_EVERY:,} steps, and where "
        "a stopped seed goes on from (default: runs/checkpoints)",
    )  # fmt: skip
    commands.choices["run"].add_argument(
        "--into", type=Path, required=True, help="folder of the results files"
    )
    args = parser.parse_args(argv)
    if args.command == "tune":
        found = tune(args.task, args.algo, args.trials, args.study, args.seed, args.steps, args.dataset,
                     args.device)  # fmt: skip
        best = found["best"]
        if best is None:
            print(f"{found['trials']} trials finished, none complete (all pruned)")
        else:
            print(
                f"{found['trials']} trials; best #{best['number']}: accuracy {best['accuracy']:.3f} in "
                f"{best['total_steps']} steps with {best['params']}"
            )
    else:
        written = run_seeds(args.task, args.algo, args.study, args.seeds, args.into, args.dataset,
                            args.device, args.steps, args.checkpoints)  # fmt: skip
        for path in written:
            report = json.loads(path.read_text())["report"]
            print(f"{path}: accuracy {report['accuracy']:.3f} in {report['total_steps']} steps")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
