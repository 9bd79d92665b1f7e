"""The library baselines' tuning protocol, run for real on a tiny budget: an Optuna search on a tuning
seed that resumes from its journal, then final runs on fresh seeds whose results files record it."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from tactile_braille.baselines import sb3
from tactile_braille.evaluation.leaderboard import leaderboard_markdown, load_results
from tactile_braille.evaluation.results import read_result

ARROWS = "tactile_braille/DiscreteArrows-v0"
REPOSITORY = Path(__file__).resolve().parents[2]


@pytest.mark.slow
def test_a_search_resumes_and_its_final_runs_record_it(env_datasets, tmp_path):
    dataset, study = env_datasets[ARROWS], tmp_path / "study"
    first = sb3.tune("DiscreteArrows-v0", "dqn", 1, study, steps=60, dataset=dataset)
    assert [t["number"] for t in first["trial_log"]] == [0] and first["trials"] == 1
    defaults = {name: sb3.DEFAULTS["dqn"][name] for name in sb3.SEARCH_SPACES["dqn"]}
    assert first["trial_log"][0]["params"] == defaults  # the untuned settings are always a trial
    again = sb3.tune("DiscreteArrows-v0", "dqn", 2, study, steps=60, dataset=dataset)
    assert [t["number"] for t in again["trial_log"]] == [0, 1]  # went on from the study: one more trial
    assert json.loads((study / "DiscreteArrows-v0__dqn.json").read_text())["best"] == again["best"]
    with pytest.raises(ValueError, match="searches with steps 60, not 90: one study, one protocol"):
        sb3.tune("DiscreteArrows-v0", "dqn", 3, study, steps=90, dataset=dataset)
    (path,) = sb3.run_seeds("DiscreteArrows-v0", "dqn", study, [7], tmp_path / "out", dataset, steps=80,
                            checkpoints=tmp_path / "checkpoints")  # fmt: skip
    assert list((tmp_path / "checkpoints").iterdir()) == []  # the seed's folder went with its results file
    tuning = read_result(path)["tuning"]
    record = tmp_path / "record"  # the search's record alone, as it travels to another machine
    record.mkdir()
    (record / "DiscreteArrows-v0__dqn.json").write_text((study / "DiscreteArrows-v0__dqn.json").read_text())
    assert sb3.search_record(record, "DiscreteArrows-v0", "dqn") == json.loads(json.dumps(again))
    assert read_result(path)["seed"] == 7
    assert read_result(path)["budget"]["env_steps"] == 80  # the final runs' budget, not the search's
    assert (tuning["trials"], tuning["seed"], tuning["steps"]) == (2, 100, 60)
    assert tuning["best"] == json.loads(json.dumps(again["best"]))
    assert tuning["space"]["goal_selection_strategy"] == {"choice": ["future", "final", "episode"]}
    assert "| 2 trials of 60 steps |" in leaderboard_markdown(load_results([path]))


def test_the_protocol_refuses_to_tune_on_reported_seeds_or_report_tuning_seeds(tmp_path):
    with pytest.raises(ValueError, match="a search trains on tuning seeds"):
        sb3.tune("DiscreteArrows-v0", "dqn", 1, tmp_path, seed=0)
    with pytest.raises(ValueError, match=r"seeds \[100\] are tuning seeds"):
        sb3.run_seeds("DiscreteArrows-v0", "dqn", tmp_path, [0, 100], tmp_path / "out")
    with pytest.raises(FileNotFoundError, match=r"no study at .* and no record of one at"):
        sb3.run_seeds("DiscreteArrows-v0", "dqn", tmp_path, [0], tmp_path / "out")
    (tmp_path / "DiscreteArrows-v0__dqn.json").write_text(
        json.dumps({"task": "DiscreteArrows-v0", "algo": "qrdqn"})
    )
    with pytest.raises(ValueError, match="is no record of a search of dqn on DiscreteArrows-v0"):
        sb3.run_seeds("DiscreteArrows-v0", "dqn", tmp_path, [0], tmp_path / "out")
    assert not (tmp_path / "out").exists()
    assert [sb3.official_budget(task) for task in ("DiscreteArrows-v0", ARROWS)] == [6_250, 6_250]


def test_each_algorithm_is_refused_on_the_other_kind_of_actions_before_any_study_is_made(tmp_path):
    assert sb3.ALGORITHMS.keys() == sb3.DEFAULTS.keys() == sb3.SEARCH_SPACES.keys()
    for algo, kind in ((name, algorithm.actions) for name, algorithm in sb3.ALGORITHMS.items()):
        task = "DiscreteArrows-v0" if kind == "continuous" else "ContinuousArrows-v0"
        with pytest.raises(ValueError, match=f"{algo} takes {kind} actions; {task}'s are "):
            sb3.tune(task, algo, 1, tmp_path / "study")
        assert {name for name in sb3.SEARCH_SPACES[algo]} <= set(sb3.DEFAULTS[algo])
    with pytest.raises(ValueError, match="algo must be one of"):
        sb3.tune("DiscreteArrows-v0", "crossq", 1, tmp_path / "study")
    assert not (tmp_path / "study").exists()


@pytest.mark.slow
@pytest.mark.parametrize(
    ("algo", "task"), [("qrdqn", ARROWS), ("tqc", "tactile_braille/ContinuousArrows-v0")]
)
def test_the_contrib_algorithms_learn_with_her_and_type(env_datasets, algo, task):
    """SB3-Contrib's QR-DQN and TQC train on the images and goals with SB3's HER buffer, and type."""
    name = task.removeprefix("tactile_braille/")
    settings = {**sb3.DEFAULTS[algo], "learning_starts": 30, "batch_size": 8}
    model, _ = sb3.train(name, algo, settings, 80, seed=0, dataset=env_datasets[task])
    assert type(model).__module__.startswith("sb3_contrib") and model.num_timesteps == 80
    report = sb3.score(model, name, env_datasets[task])
    assert 0.0 <= report.accuracy <= 1.0 and report.total_steps >= report.keys_asked


class Stopped(Exception):
    """The process stopping (killed, the machine taken back) right after a checkpoint."""


@pytest.mark.slow
def test_a_stopped_run_goes_on_from_its_latest_checkpoint(env_datasets, tmp_path, monkeypatch):
    dataset, folder = env_datasets[ARROWS], tmp_path / "checkpoints"
    settings = {"learning_starts": 30, "batch_size": 8}  # past the first episode (HER samples whole ones)
    save = sb3._save_checkpoint

    def train(seed):
        return sb3.train(
            "DiscreteArrows-v0", "dqn", settings, 60, seed, dataset, checkpoints=folder, every=20
        )

    def save_then_stop(model, where, seconds):
        save(model, where, seconds)
        if model.num_timesteps == 40:
            raise Stopped

    monkeypatch.setattr(sb3, "_save_checkpoint", save_then_stop)
    with pytest.raises(Stopped):
        train(seed=3)
    assert sorted(p.name for p in folder.iterdir()) == ["run.json", "step-40"]  # the older one removed
    monkeypatch.setattr(sb3, "_save_checkpoint", save)
    (folder / ".step-60.partial").mkdir()  # a save cut short is not a checkpoint
    with pytest.raises(ValueError, match=r"holds checkpoints of another run \(its \['seed'\] differ\)"):
        train(seed=4)
    model, seconds = train(seed=3)
    assert model.num_timesteps == 60 and seconds > 0
    assert model.replay_buffer.size() == 59  # 39 stored before the stop (the 40th on its way), 20 after
    assert model._n_updates == 29  # 9 before the stop (steps 31-39) carried on, and 20 after
    assert sorted(p.name for p in folder.iterdir()) == ["run.json", "step-40"]  # none at the budget's end


def test_the_committed_searches_read_and_their_final_runs_carry_them_whole():
    """Each record in results/searches reads as a finished search of its task and algorithm, on a tuning
    seed, within its search space; the tuned results files of that task and algorithm carry it unchanged,
    at the task's official budget."""
    records = sorted((REPOSITORY / "results" / "searches").glob("*.json"))
    records = [r for r in records if json.loads(r.read_text())["library"] != "tactile_braille"]  # libraries
    assert records
    for record in records:
        task, algo = record.stem.split("__")
        tuning = sb3.search_record(record.parent, task, algo)
        assert tuning["seed"] in sb3.TUNING_SEEDS and tuning["trials"] == len(tuning["trial_log"])
        assert tuning["steps"] <= sb3.official_budget(task)
        assert set(tuning["best"]["params"]) == set(sb3.SEARCH_SPACES[algo])
        tuned = REPOSITORY / "results" / "leaderboard" / "sb3-tuned"
        for final in sorted(tuned.glob(f"{task}__{algo}__*.json")):
            result = read_result(final)
            assert result["tuning"] == tuning, final.name
            assert result["budget"]["env_steps"] == sb3.official_budget(task)
