"""Our agents tuned by the benchmark's protocol, run for real on a tiny budget: an Optuna search of the
planner's settings on a tuning seed that goes on from its study, pruning's typing checks from inside the
training loop, then final runs on fresh seeds whose records carry the search."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from tactile_braille import tuning
from tactile_braille._tasks import REGISTERED_TASKS
from tactile_braille.agents.config import TrainConfig
from tactile_braille.agents.presets import preset_config
from tactile_braille.agents.registry import agent_names, agent_spec
from tactile_braille.evaluation.leaderboard import leaderboard_markdown, load_results
from tactile_braille.evaluation.results import read_result
from tactile_braille.evaluation.runs import run_method
from tactile_braille.search import TUNING_SEEDS, Choice, Range, check_untuned

ARROWS = "tactile_braille/DiscreteArrows-v0"
REPOSITORY = Path(__file__).resolve().parents[1]


@pytest.mark.slow
def test_a_search_of_the_planner_goes_on_and_its_final_runs_carry_it(env_datasets, tmp_path, monkeypatch):
    machine = {"epochs": 3, "dataset": str(env_datasets[ARROWS]), "precision": "fp32", "threads": 1}
    study, checks = tmp_path / "study", []
    from tactile_braille import search

    objective = search.objective

    def noted(report):  # every typing the search scores: two checks, then the trial's end
        checks.append(report.total_steps)
        return objective(report)

    monkeypatch.setattr(search, "objective", noted)
    first = tuning.tune("DiscreteArrows-v0", "planner", "fast-tactile", 1, study, machine=machine)
    assert first["trials"] == 1 and len(checks) == 3  # at a third, two thirds and the end of 750 steps
    untuned = tuning.untuned("DiscreteArrows-v0", "planner", "fast-tactile")
    assert first["trial_log"][0]["params"] == untuned == first["defaults"]  # the preset's settings first
    assert first["steps"] == 750 and first["seed"] == 100 and first["preset"] == "fast-tactile"
    again = tuning.tune("DiscreteArrows-v0", "planner", "fast-tactile", 2, study, machine=machine)
    assert [t["number"] for t in again["trial_log"]] == [0, 1]  # went on from the study: one more trial
    assert not list((study / "trials").iterdir())  # each trial's run folder went once it was scored
    with pytest.raises(ValueError, match="searches with steps 750, not 500: one study, one protocol"):
        tuning.tune("DiscreteArrows-v0", "planner", "fast-tactile", 3, study,
                    machine={**machine, "epochs": 2})  # fmt: skip

    (record,) = tuning.run_seeds("DiscreteArrows-v0", "planner", "fast-tactile", study, [7],
                                 tmp_path / "runs", tmp_path / "records", machine)  # fmt: skip
    result = read_result(record / "result.json")
    best = again["best"]["params"]
    assert result["tuning"] == json.loads(json.dumps(again)) and result["seed"] == 7
    config = TrainConfig.from_json(json.loads((record / "config.json").read_text()))
    assert {name: getattr(config.agent, name) for name in best} == best  # the best trial's settings ran
    assert result["method"] == run_method(config, tuned=True)
    assert result["method"].startswith("tactile_braille planner (`fast-tactile`, tuned")
    assert "| 2 trials |" in leaderboard_markdown(load_results([record]))
    assert result["tuning"]["seeds"] == [100]

    # Several tuning seeds: each trial trains on each in turn, and scores their mean.
    several = tuning.tune("DiscreteArrows-v0", "planner", "fast-tactile", 1, tmp_path / "several",
                          seeds=(101, 102), machine={**machine, "epochs": 1})  # fmt: skip
    (trial,) = several["trial_log"]
    assert several["seeds"] == [101, 102] and several["objective"].endswith("the mean over the tuning seeds")
    assert len(trial["per_seed"]) == 2 and trial["accuracy"] == pytest.approx(
        sum(accuracy for accuracy, _ in trial["per_seed"]) / 2
    )
    with pytest.raises(ValueError, match=r"searches with seeds \[101, 102\], not \[101\]"):
        tuning.tune("DiscreteArrows-v0", "planner", "fast-tactile", 2, tmp_path / "several", seeds=(101,),
                    machine={**machine, "epochs": 1})  # fmt: skip

    again_records = tuning.run_seeds("DiscreteArrows-v0", "planner", "fast-tactile", study, [7],
                                     tmp_path / "runs", tmp_path / "records", machine)  # fmt: skip
    assert again_records == [record] and read_result(record / "result.json") == result  # not run again


def test_a_search_is_refused_before_any_study_is_made(tmp_path):
    with pytest.raises(ValueError, match="a search trains on tuning seeds"):
        tuning.tune("DiscreteArrows-v0", "planner", "fast-tactile", 1, tmp_path, seeds=(100, 0))
    with pytest.raises(ValueError, match=r"dqn has no search space \(DQNConfig.search_space is empty\)"):
        tuning.tune("DiscreteArrows-v0", "dqn", "paper", 1, tmp_path)
    with pytest.raises(ValueError, match=r"\['replay'\] are not machine settings"):
        tuning.tune("DiscreteArrows-v0", "planner", "fast-tactile", 1, tmp_path, machine={"replay": {}})
    with pytest.raises(ValueError, match=r"seeds \[100\] are tuning seeds"):
        tuning.run_seeds("DiscreteArrows-v0", "planner", "fast-tactile", tmp_path, [0, 100], tmp_path / "r",
                         tmp_path / "out")  # fmt: skip
    with pytest.raises(FileNotFoundError, match=r"no study at .* and no record of one at"):
        tuning.run_seeds("DiscreteArrows-v0", "planner", "fast-tactile", tmp_path, [0], tmp_path / "r",
                         tmp_path / "out")  # fmt: skip
    record = tmp_path / "DiscreteArrows-v0__planner__fast-tactile.json"
    record.write_text(json.dumps({"library": "tactile_braille", "algo": "planner", "preset": "paper",
                                  "task": "DiscreteArrows-v0"}))  # fmt: skip
    with pytest.raises(ValueError, match="no record of a search of planner from the `fast-tactile` preset"):
        tuning.search_record(tmp_path, "DiscreteArrows-v0", "planner", "fast-tactile")
    assert sorted(p.name for p in tmp_path.iterdir()) == [record.name]


def test_the_untuned_settings_must_lie_in_the_space():
    space = {"gamma": Choice((0.9, 0.95)), "learning_rate": Range(1e-4, 1e-3, log=True)}
    check_untuned(space, {"gamma": 0.9, "learning_rate": 1e-3})
    with pytest.raises(ValueError, match=r"gamma: 0.99 is none of \[0.9, 0.95\]; learning_rate: 0.01 is "
                       r"outside \[0.0001, 0.001\]"):  # fmt: skip
        check_untuned(space, {"gamma": 0.99, "learning_rate": 1e-2})
    with pytest.raises(ValueError, match="learning_rate: none given"):
        check_untuned(space, {"gamma": 0.9})
    for task in (registered.env_id for registered in REGISTERED_TASKS):
        check_untuned(tuning.search_space("planner"), tuning.untuned(task, "planner", "fast-tactile"))
        check_untuned(tuning.search_space("mrq"), tuning.untuned(task, "mrq", "paper"))


def test_a_tuned_runs_method_says_so_and_names_what_the_search_changed():
    config = preset_config("fast-tactile", ARROWS, "planner")
    assert run_method(config, tuned=True) == "tactile_braille planner (`fast-tactile`, tuned)"
    changed = preset_config("fast-tactile", ARROWS, "planner", agent={"gamma": 0.95})
    tuned = "tactile_braille planner (`fast-tactile`, tuned: agent.gamma=0.95)"
    assert run_method(changed, tuned=True) == tuned
    assert run_method(changed) == "tactile_braille planner (`fast-tactile`, agent.gamma=0.95)"


def test_the_committed_searches_of_our_agents_read_and_their_final_runs_carry_them_whole():
    """Each record of a search of one of our agents under results/searches reads as a finished search on
    tuning seeds within the agent's space, and five or more tuned records (results/tuned*/) carry it
    unchanged and ran its best settings; every tuned record carries one of them."""
    records = sorted((REPOSITORY / "results" / "searches").glob("**/*__*__*.json"))
    assert records
    searches = []
    for record in records:
        task, algo, preset = record.stem.split("__")
        found = tuning.search_record(record.parent, task, algo, preset)
        assert set(found.get("seeds") or [found["seed"]]) <= set(TUNING_SEEDS)
        assert found["trials"] == len(found["trial_log"])
        assert set(found["best"]["params"]) == set(found["space"]) <= set(tuning.search_space(algo))
        searches.append([found, 0])
    for final in sorted((REPOSITORY / "results").glob("tuned*/*/result.json")):
        config = TrainConfig.from_json(json.loads((final.parent / "config.json").read_text()))
        carried = read_result(final)["tuning"]
        (entry,) = [entry for entry in searches if entry[0] == carried]  # one committed search, whole
        entry[1] += 1
        assert config.preset == carried["preset"] and config.seed not in TUNING_SEEDS
        best = carried["best"]["params"]
        assert {name: getattr(config.agent, name) for name in best} == best, final
    assert all(count >= 5 for _, count in searches), [(f["task"], f.get("seeds"), n) for f, n in searches]


def test_a_study_keeps_the_space_it_searched(tmp_path):
    """A study records its search space: a search of another space is refused, and its record gives the
    space it searched, not the code's of the day."""
    from tactile_braille import search

    study, identity = tmp_path / "T__a.db", {"library": "x", "algo": "a", "task": "T"}
    narrow, wide = {"gamma": Choice((0.9, 0.95))}, {"gamma": Choice((0.7, 0.9, 0.95))}
    record = search.search(study, identity, narrow, {"gamma": 0.9}, 0, [100], 10, None)  # no trial to run
    assert record["space"] == {"gamma": {"choice": [0.9, 0.95]}} and record["trials"] == 0
    with pytest.raises(ValueError, match=r"searches with space .*0\.95.*, not .*0\.7.*: one study"):
        search.search(study, identity, wide, {"gamma": 0.9}, 0, [100], 10, None)
    assert (
        search.summary(search.open_study(study, "T__a", create=False), identity, wide, {})["space"]
        == (record["space"])
    )


def test_every_point_a_search_space_names_makes_a_run_the_agent_accepts():
    """A trial must never fail on its settings: each agent's every choice, and its ranges' ends, make a
    valid run of the preset the agent is searched from, on every task it learns."""
    searched = {name: agent_spec(name) for name in agent_names() if agent_spec(name).config.search_space}
    assert {"planner", "mrq"} <= set(searched)
    for algo, spec in searched.items():
        preset = "fast-tactile" if algo == "planner" else "paper"
        for task in (registered.env_id for registered in REGISTERED_TASKS):
            for name, dim in spec.config.search_space.items():
                for value in (dim.low, dim.high) if isinstance(dim, Range) else dim:
                    config = preset_config(preset, task, algo, seed=100, agent={name: value})
                    assert getattr(config.agent, name) == value, (algo, task, name)
