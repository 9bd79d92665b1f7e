"""Scoring any agent: evaluate_policy on callables, its fingerprint, results files and the leaderboard."""

from __future__ import annotations

import json
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
import torch

import tactile_braille  # noqa: F401 - registers the environments
from tactile_braille.agents.config import TrainConfig
from tactile_braille.agents.presets import preset_config
from tactile_braille.cli import main
from tactile_braille.envs.oracle import oracle_action
from tactile_braille.envs.tasks import DISCRETE_ACTIONS
from tactile_braille.evaluation import PolicyError, TypingReport, evaluate_policy, scoring, touch_optimum
from tactile_braille.evaluation.leaderboard import (
    HEADLINE_MARKERS,
    headline_markdown,
    leaderboard_markdown,
    load_results,
    write_headline,
)
from tactile_braille.evaluation.protocol import paper_sequences
from tactile_braille.evaluation.results import make_result, read_result, seal, write_result
from tactile_braille.evaluation.runs import run_method

ARROWS = "tactile_braille/DiscreteArrows-v0"
CONTINUOUS = "tactile_braille/ContinuousArrows-v0"
PRESS = DISCRETE_ACTIONS.index("PRESS")
ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture
def arrows(env_datasets):
    return gym.make(ARROWS, dataset=env_datasets[ARROWS])


@pytest.fixture
def continuous(env_datasets):
    return gym.make(CONTINUOUS, dataset=env_datasets[CONTINUOUS])


def press(observation):
    return PRESS


def test_a_random_callable_gets_a_full_report(env_datasets):
    rng = np.random.default_rng(0)
    report = evaluate_policy(
        lambda o: int(rng.integers(5)), "DiscreteArrows-v0", dataset=env_datasets[ARROWS]
    )
    assert isinstance(report, TypingReport) and report.task == "DiscreteArrows-v0"
    assert report.keys_asked == 96 and report.sequences == 24 and 0.0 <= report.accuracy <= 1.0
    assert 96 <= report.total_steps <= 96 * 25
    assert len(report.fingerprint) == 64 and int(report.fingerprint, 16) >= 0
    assert np.sum(report.confusion["counts"]) == 96
    assert report.track == "tactile" and report.protocol == "paper"
    assert report.touch_optimum == pytest.approx(touch_optimum("arrows", paper_sequences("arrows"), "paper"))


def test_a_callable_that_reads_the_pose_types_everything_right(arrows):
    report = evaluate_policy(lambda observation: oracle_action(arrows), ARROWS, env=arrows)
    assert report.accuracy == 1.0 and report.confusion["counts"] == [
        [24 if row == column else 0 for column in range(6)] for row in range(4)
    ]


def test_our_agents_and_a_callable_acting_alike_get_the_same_report(arrows):
    class Agent:
        def policy_action(self, observation, step, explore, rng, deterministic=False):
            assert deterministic and not explore
            return PRESS

    ours, theirs = evaluate_policy(Agent(), ARROWS, env=arrows), evaluate_policy(press, ARROWS, env=arrows)
    assert ours.to_dict() == theirs.to_dict()


@pytest.mark.parametrize(
    "action",
    [np.int64(PRESS), np.array(PRESS), np.array([PRESS]), torch.tensor(PRESS), torch.tensor([PRESS])],
    ids=["numpy-int", "0-d array (SB3 predict)", "array of one", "tensor", "tensor of one"],
)
def test_integer_actions_in_any_array_form_are_taken(arrows, action):
    report = evaluate_policy(lambda o: action, ARROWS, env=arrows)
    assert report.to_dict() == evaluate_policy(press, ARROWS, env=arrows).to_dict()


@pytest.mark.parametrize(
    ("task", "action", "message"),
    [
        (ARROWS, 1.0, "takes one integer"),
        (ARROWS, np.array([1, 2]), "shape (2,)"),
        (ARROWS, 7, "outside DiscreteArrows-v0's Discrete(5)"),
        (ARROWS, "PRESS", "takes one integer"),
        (CONTINUOUS, np.zeros(2, np.float32), "float array of shape (3,)"),
        (CONTINUOUS, np.zeros((1, 3), np.float32), "float array of shape (3,)"),
        (CONTINUOUS, np.zeros(3, np.int64), "float array of shape (3,)"),
        (CONTINUOUS, np.array([0.0, np.nan, 0.0]), "non-finite"),
        (CONTINUOUS, np.array([0.0, 1.5, 0.0]), "outside ContinuousArrows-v0's action space"),
        (CONTINUOUS, None, "for ContinuousArrows-v0"),
    ],
)
def test_bad_actions_are_refused_with_what_is_wrong(arrows, continuous, task, action, message):
    env = arrows if task == ARROWS else continuous
    with pytest.raises(PolicyError, match=message.replace("(", r"\(").replace(")", r"\)")):
        evaluate_policy(lambda o: action, task, env=env)


def test_bad_settings_are_refused(arrows):
    with pytest.raises(ValueError, match="unknown task 'Typing-v0'; choose one of"):
        evaluate_policy(press, "Typing-v0")
    with pytest.raises(ValueError, match="protocol must be one of"):
        evaluate_policy(press, ARROWS, env=arrows, protocol="fast")
    with pytest.raises(ValueError, match="track must be one of"):
        evaluate_policy(press, ARROWS, env=arrows, track="vision")
    with pytest.raises(TypeError, match="must be callable"):
        evaluate_policy(3, ARROWS, env=arrows)
    with pytest.raises(ValueError, match="the environment is tactile_braille/DiscreteArrows-v0, not"):
        evaluate_policy(press, "ContinuousArrows-v0", env=arrows)


def never_press(observation):
    return DISCRETE_ACTIONS.index("UP")


class Counted:
    """A policy that fails the test once called more often than ``most`` times (a loop without end)."""

    def __init__(self, policy, most: int) -> None:
        self.policy, self.most, self.calls = policy, most, 0

    def __call__(self, observation):
        self.calls += 1
        assert self.calls <= self.most, f"called {self.calls} times: the protocol's limit was not imposed"
        return self.policy(observation)


@pytest.mark.parametrize(("limit", "steps"), [(None, 25), (10, 10)], ids=["registered", "given"])
def test_the_protocols_episode_limit_holds_in_an_environment_without_one(arrows, limit, steps):
    """An unwrapped environment has no time limit: a policy that never presses still ends each key at
    the protocol's limit (the registered 25 steps, or the one given), as the fingerprint records."""
    policy = Counted(never_press, 96 * steps)
    report = evaluate_policy(policy, ARROWS, env=arrows.unwrapped, max_episode_steps=limit, sentences=False)
    assert report.total_steps == 96 * steps and report.accuracy == 0.0
    assert report.conditions["max_episode_steps"] == steps
    assert [row[-1] for row in report.confusion["counts"]] == [24] * 4  # every key timed out (NONE)


def test_a_longer_time_limit_is_cut_to_the_protocols_and_a_shorter_one_refused(arrows):
    longer = gym.wrappers.TimeLimit(arrows.unwrapped, 1000)
    report = evaluate_policy(Counted(never_press, 96 * 25), ARROWS, env=longer)
    assert report.total_steps == 96 * 25
    assert report.fingerprint == evaluate_policy(never_press, ARROWS, env=arrows).fingerprint
    shorter = gym.wrappers.TimeLimit(arrows.unwrapped, 10)
    with pytest.raises(ValueError, match=r"time limit \(10 steps\) cuts keys short of the protocol's 25"):
        evaluate_policy(never_press, ARROWS, env=shorter)
    with pytest.raises(ValueError, match="max_episode_steps must be a positive integer or None, got 0"):
        evaluate_policy(never_press, ARROWS, env=arrows, max_episode_steps=0)


def test_a_long_evaluation_shows_its_progress(arrows, capsys):
    evaluate_policy(press, ARROWS, env=arrows, progress=True)
    assert "typing paper" in capsys.readouterr().err
    evaluate_policy(press, ARROWS, env=arrows)
    assert capsys.readouterr().err == ""


def test_arguments_of_the_wrong_kind_are_refused_before_anything_is_made(arrows, env_datasets, tmp_path):
    missing = tmp_path / "no-such-dataset.h5"  # made first, the environment would fail on it instead
    with pytest.raises(TypeError, match="a policy must be callable"):
        evaluate_policy(3, ARROWS, dataset=missing)
    with pytest.raises(TypeError, match=r"task must be a task's name \(e.g. 'DiscreteArrows-v0'\), got int"):
        evaluate_policy(press, 3, dataset=missing)
    with pytest.raises(TypeError, match="pass the environment as env="):
        evaluate_policy(press, arrows)
    with pytest.raises(TypeError, match=r"env must be a gymnasium\.Env of the task"):
        evaluate_policy(press, ARROWS, env="DiscreteArrows-v0")
    vector = gym.vector.SyncVectorEnv([lambda: gym.make(ARROWS, dataset=env_datasets[ARROWS])] * 2)
    with pytest.raises(TypeError, match="env is a vector environment of 2; typing is scored in one"):
        evaluate_policy(press, ARROWS, env=vector)


def test_the_fingerprint_changes_with_what_decides_the_score(arrows, monkeypatch):
    base = evaluate_policy(press, ARROWS, env=arrows)
    assert evaluate_policy(press, ARROWS, env=arrows).fingerprint == base.fingerprint
    # Everything that decides the score moves it: the start seed, the protocol, the episode limit...
    assert evaluate_policy(press, ARROWS, env=arrows, seed=1).fingerprint != base.fingerprint
    assert evaluate_policy(press, ARROWS, env=arrows, protocol="released").fingerprint != base.fingerprint
    shorter = gym.make(ARROWS, dataset=arrows.unwrapped.world["dataset"], max_episode_steps=10)
    assert evaluate_policy(press, ARROWS, env=shorter, max_episode_steps=10).fingerprint != base.fingerprint
    # ... the project's version ...
    monkeypatch.setattr(scoring, "__version__", "9.9.9")
    assert evaluate_policy(press, ARROWS, env=arrows).fingerprint != base.fingerprint
    monkeypatch.undo()
    # ... and the world: a sensor parameter (live renders of two sensors).
    rendered = {
        sensor: evaluate_policy(press, ARROWS, env=gym.make(ARROWS, backend="render", sensor=sensor))
        for sensor in ("braille_331", "tactip_127")
    }
    assert len({r.fingerprint for r in rendered.values()} | {base.fingerprint}) == 3
    # Not where the dataset file lies: a copy elsewhere scores under the same fingerprint.
    conditions = dict(base.conditions, world={**base.conditions["world"], "dataset": "/elsewhere.h5"})
    moved = scoring.protocol_conditions(ARROWS, "paper", conditions["sequences"], 25, 0, conditions["world"])
    assert scoring.fingerprint(moved) == base.fingerprint


def test_the_fingerprint_covers_the_datasets_samples(env_datasets, tmp_path, monkeypatch):
    """Two datasets of the same parameters but other samples (frames mirrored, the file's digest made
    anew) are two worlds; a default dataset holding the reference generation's samples is named by its
    parameters alone, as the leaderboard's results were scored."""
    import h5py

    from tactile_braille.datasets import cache
    from tactile_braille.datasets.store import load_dataset, samples_digest

    original = load_dataset(env_datasets[ARROWS])
    mirrored = tmp_path / "mirrored.h5"
    mirrored.write_bytes(env_datasets[ARROWS].read_bytes())
    with h5py.File(mirrored, "r+") as handle:
        frames = handle["observations"][()][:, :, ::-1]
        del handle["observations"]
        handle.create_dataset("observations", data=frames)
        arrays = {
            name: handle[name][()] for name in ("observations", "poses", "labels", "pressed", "tap_index")
        }
        handle.attrs["samples_sha256"] = samples_digest(arrays)
    reports = [evaluate_policy(press, ARROWS, dataset=path) for path in (env_datasets[ARROWS], mirrored)]
    worlds = [report.conditions["world"] for report in reports]
    assert worlds[0]["samples_sha256"] == original.samples_sha256 != worlds[1]["samples_sha256"]
    assert reports[0].fingerprint != reports[1].fingerprint
    # As a reference generation (here: the small dataset made the reference), no digest in the world.
    version = original.metadata.generator_version
    monkeypatch.setattr(cache, "REFERENCE_SAMPLES", {version: {"keys-train": original.samples_sha256}})
    monkeypatch.setattr(cache, "_default_collection", lambda *args: (None, None, original.metadata))
    world = evaluate_policy(press, ARROWS, dataset=env_datasets[ARROWS]).conditions["world"]
    assert "samples_sha256" not in world and world == {
        k: v for k, v in worlds[0].items() if k != "samples_sha256"
    }


def test_the_reference_samples_name_every_default_dataset_of_this_generator():
    from tactile_braille.datasets.cache import DEFAULT_DATASETS, REFERENCE_SAMPLES
    from tactile_braille.datasets.collector import GENERATOR_VERSION

    assert set(REFERENCE_SAMPLES[GENERATOR_VERSION]) == set(DEFAULT_DATASETS)


@pytest.mark.slow
def test_a_fresh_generation_of_a_default_dataset_holds_the_reference_samples(tmp_path, monkeypatch):
    """The leaderboard's fingerprints name the default datasets by their parameters: a generation on
    this machine must hold the reference samples (else results scored here carry their digest)."""
    from tactile_braille.datasets.cache import REFERENCE_SAMPLES, default_dataset
    from tactile_braille.datasets.collector import GENERATOR_VERSION

    monkeypatch.setenv("TACTILE_BRAILLE_DATA", str(tmp_path))
    dataset = default_dataset("keys-validation", progress=False)
    assert dataset.samples_sha256 == REFERENCE_SAMPLES[GENERATOR_VERSION]["keys-validation"]


def test_touch_optimum_has_known_values():
    # Arrows, a reset per key: from a uniform start cell, 24 x 4 keys (docs/evaluation.md).
    assert touch_optimum("arrows", paper_sequences("arrows"), "released") == pytest.approx(228.0)
    assert touch_optimum("arrows", paper_sequences("arrows"), "paper") == pytest.approx(237.0)
    with pytest.raises(ValueError, match="protocol must be one of"):
        touch_optimum("arrows", paper_sequences("arrows"), "fast")


# ---------------------------------------------------------------- results files
def _result(arrows, method="press at once", seed=0, notes="", **options):
    return make_result(evaluate_policy(press, ARROWS, env=arrows, **options), method=method, seed=seed,
                       env_steps=0, notes=notes)  # fmt: skip


def _with_seed(result: dict, seed: int) -> dict:
    """``result`` as its method would have written it for training seed ``seed``: sealed again."""
    changed = {name: value for name, value in result.items() if name != "seal"} | {"seed": seed}
    return {**changed, "seal": seal(changed)}


def test_a_results_file_round_trips_and_refuses_edits(arrows, tmp_path):
    result = _result(arrows)
    path = write_result(result, tmp_path / "sub" / "press.json")
    assert read_result(path) == json.loads(json.dumps(result))
    with pytest.raises(FileExistsError, match="exists; choose another name"):
        write_result(result, path)
    write_result(result, path, overwrite=True)
    edited = json.loads(path.read_text())
    edited["report"]["conditions"]["max_episode_steps"] = 50
    path.write_text(json.dumps(edited))
    with pytest.raises(ValueError, match="fingerprint does not match the conditions"):
        read_result(path)
    path.write_text(json.dumps({"format": "something/else"}))
    with pytest.raises(ValueError, match="not a results file of format"):
        read_result(path)
    path.write_text("{truncated")
    with pytest.raises(ValueError, match="not a readable results file"):
        read_result(path)
    with pytest.raises(ValueError, match="needs a method name"):
        make_result(evaluate_policy(press, ARROWS, env=arrows), method=" ")
    with pytest.raises(ValueError, match="env_steps must be a non-negative integer"):
        make_result(evaluate_policy(press, ARROWS, env=arrows), method="x", env_steps=-1)


def _set(*edits):
    """Edits of a results file's fields: (path, value) pairs, a path such as ``report.accuracy`` or
    ``report.confusion.counts.0.0``, a value or a function of the old one."""

    def edit(result):
        for path, value in zip(edits[::2], edits[1::2], strict=True):
            *parents, last = (int(name) if name.isdigit() else name for name in path.split("."))
            node = result
            for name in parents:
                node = node[name]
            node[last] = value(node[last]) if callable(value) else value
        return result

    return edit


def _more_steps(result):
    report = result["report"]
    steps = report["total_steps"] + 1
    return _set("report.total_steps", steps, "report.steps_per_key", steps / report["keys_asked"])(result)


def _without(name: str):
    """An edit that removes a field and its digest from the seal (``report.touch_optimum``)."""

    def edit(result):
        parent, _, field = name.rpartition(".")
        (result[parent] if parent else result).pop(field)
        result["seal"].pop(name)
        return result

    return edit


def _no_sequences(result):
    conditions = {**result["report"]["conditions"], "sequences": []}
    digest = scoring.fingerprint(conditions)
    return _set("report.conditions", conditions, "report.fingerprint", digest, "fingerprint", digest)(result)


EDITS = {
    "accuracy raised, plausibly": (_set("report.accuracy", 0.99),
                                   r"accuracy \(0\.99\) contradicts its confusion matrix \(\d+ of 96"),
    "accuracy above 1": (_set("report.accuracy", 1.7), r"accuracy must be a number in \[0, 1\], got 1\.7$"),
    "accuracy NaN": (_set("report.accuracy", float("nan")), r"accuracy must .*, got nan$"),
    "accuracy a word": (_set("report.accuracy", "high"), r"accuracy must .*, got 'high'$"),
    "steps fewer than keys": (_set("report.total_steps", 50), r"report\.total_steps \(50\) must lie between"),
    "steps per key left": (_set("report.total_steps", lambda n: n + 1), r"steps_per_key \(8\.0\) is not"),
    "steps edited, in range": (_more_steps, r"\['report\.total_steps', 'report\.steps_per_key'\] were"),
    "keys asked edited": (_set("report.keys_asked", 100), r"differ from the 96 keys in 24 sequences"),
    "confusion edited": (_set("report.confusion.counts.0.0", lambda n: n + 1), r"counts \d+ goals 'UP'"),
    "method renamed": (_set("method", "someone else's"), r"\['method'\] were changed after the file was"),
    "seed changed": (_set("seed", 7), r"\['seed'\] were changed"),
    "budget cut": (_set("budget.env_steps", 10), r"\['budget'\] were changed"),
    "field added": (_set("report.note", "x"), r"\['report\.note'\] were added"),
    "seal removed": (lambda r: {k: v for k, v in r.items() if k != "seal"}, r"lacks \['seal'\]"),
    "field removed with its seal": (_without("method"), r"lacks \['method'\]"),
    "report field removed, sealed": (_without("report.touch_optimum"), r"report lacks \[.touch_optimum.\]"),
    "no sequences, fingerprinted anew": (_no_sequences, r"sequences must be a non-empty list"),
    "unsealed format": (_set("format", "tactile_braille.result/1"), r"written before results files were"),
}  # fmt: skip


@pytest.mark.parametrize("edit, message", EDITS.values(), ids=EDITS)
def test_an_edited_results_file_is_refused_naming_the_field(arrows, tmp_path, capsys, edit, message):
    """The numbers are checked against each other and the file against its seal: an edit, plausible or
    impossible, is refused by the reader and by the leaderboard, in one line."""
    path = write_result(_result(arrows), tmp_path / "press.json")
    path.write_text(json.dumps(edit(json.loads(path.read_text()))))
    with pytest.raises(ValueError, match=message):
        read_result(path)
    assert main(["leaderboard", str(path), "--output", str(tmp_path / "board.md")]) == 2
    error = capsys.readouterr().err
    assert error.count("\n") == 1 and "Traceback" not in error and not (tmp_path / "board.md").exists()


def test_a_perfect_typing_cannot_claim_fewer_steps_than_the_world_allows(arrows, tmp_path):
    oracle = make_result(
        evaluate_policy(lambda o: oracle_action(arrows), ARROWS, env=arrows), method="oracle"
    )
    assert oracle["report"]["accuracy"] == 1.0 and oracle["report"]["typing_bound"] == 242
    edited = {**oracle, "report": {**oracle["report"], "total_steps": 200, "steps_per_key": 200 / 96}}
    with pytest.raises(ValueError, match=r"total_steps \(200\) is below the fewest steps the world allows"):
        write_result(edited, tmp_path / "oracle.json")
    assert not (tmp_path / "oracle.json").exists()


def test_the_leaderboard_ranks_one_fingerprint_and_shows_others_apart(arrows, tmp_path):
    oracle = evaluate_policy(lambda o: oracle_action(arrows), ARROWS, env=arrows)
    results = [
        ("a.json", make_result(oracle, method="pose oracle", seed=0, env_steps=0)),
        ("b.json", _result(arrows, seed=0)),
        ("c.json", _result(arrows, seed=1)),
        ("d.json", _result(arrows, method="press, reset per key", protocol="released")),
    ]
    page = leaderboard_markdown(results, title="Test board")
    assert page.startswith("# Test board")
    ranked = page.split("### Under other conditions")[0]
    assert ranked.index("| 1 | pose oracle | tactile | 1 | 1.000 |") < ranked.index(
        "| 2 | press at once | tactile | 2 |"
    )
    assert "Church et al. 2020, Table III (sim): DQN | tactile | - | 1.000 | 230 |" in ranked
    apart = page.split("### Under other conditions")[1]
    assert "press, reset per key" in apart and 'protocol: "paper" -> "released"' in apart
    with pytest.raises(ValueError, match=r"d\.json was scored under other conditions"):
        leaderboard_markdown(results, strict=True)
    # With the released protocol as the reference, the others go apart instead.
    page = leaderboard_markdown(results, reference={"DiscreteArrows-v0": results[3][1]["fingerprint"]})
    assert "| 1 | press, reset per key | tactile |" in page.split("### Under other conditions")[0]
    # As the page shows it: 12 characters, and the task with its namespace.
    short = {"tactile_braille/DiscreteArrows-v0": results[3][1]["fingerprint"][:12]}
    assert leaderboard_markdown(results, reference=short) == page
    for bad, message in (({"DiscreteArrows-v0": "not-hex"}, "matches 0 of its results' fingerprints"),
                         ({"Typing-v0": "0000"}, "no result of that task")):  # fmt: skip
        with pytest.raises(ValueError, match=message):
            leaderboard_markdown(results, reference=bad)
    with pytest.raises(ValueError, match=r"e\.json repeats seed 0 of b\.json"):
        leaderboard_markdown([*results, ("e.json", _result(arrows, seed=0, notes="scored again"))])


def test_a_results_file_given_twice_is_refused_not_counted_as_two_seeds(arrows, tmp_path):
    """Its seed unknown (None), a results file given twice, or a copy of it, would count as two seeds."""
    first = write_result(_result(arrows, seed=None), tmp_path / "a.json")
    copy = tmp_path / "b.json"
    copy.write_text(first.read_text())
    (tmp_path / "sub").mkdir()
    for twice in ([first, first], [first, tmp_path / "sub" / ".." / "a.json"]):
        with pytest.raises(ValueError, match=r"a\.json and .*a\.json are the same results file, given twice"):
            load_results(twice)
    with pytest.raises(ValueError, match=r"a\.json and .*b\.json hold the same result \(a copy\?\)"):
        leaderboard_markdown(load_results([first, copy]))


def test_two_results_of_unknown_seed_are_not_two_seeds(arrows):
    """One method, task, track, fingerprint and budget: without their seeds, two results cannot be told
    apart as seeds (a result of a known seed and one of none neither); under two methods they can."""
    unknown = [(f"{name}.json", _result(arrows, seed=None, notes=name)) for name in ("a", "b")]
    message = r"a\.json and b\.json: two results of press at once on DiscreteArrows-v0 .* told apart"
    with pytest.raises(ValueError, match=message):
        leaderboard_markdown(unknown)
    with pytest.raises(ValueError, match=message):
        leaderboard_markdown([unknown[0], ("b.json", _result(arrows, seed=3))])
    with pytest.raises(ValueError, match=message):
        leaderboard_markdown([("a.json", _result(arrows, seed=3)), unknown[1]])
    other = ("b.json", _result(arrows, seed=None, method="press, again"))
    assert "| press at once | tactile | 1 |" in leaderboard_markdown([unknown[0], other])


def test_the_reference_is_the_registered_conditions_however_many_results_hold_others(arrows):
    """A task's reference is its registered conditions (the paper's protocol, the dataset backend, typing
    start seed 0, the registry's limit), never the conditions most results hold: neither typing from
    start seed 1 nor a live render, recorded as such, flips it."""
    rendered = evaluate_policy(press, ARROWS, backend="render")
    assert rendered.conditions["world"]["backend"] == "render"  # not "rig": the env makes its own rig
    others = [
        make_result(evaluate_policy(press, ARROWS, env=arrows, seed=1), method="press at once", env_steps=0),
        make_result(rendered, method="press at once", env_steps=0),
        make_result(evaluate_policy(press, ARROWS, env=arrows.unwrapped, max_episode_steps=30),
                    method="press at once", env_steps=0),
    ]  # fmt: skip
    registered = ("ours.json", _result(arrows, method="ours", seed=0))
    results = [(f"{n}-{seed}.json", _with_seed(r, seed)) for n, r in enumerate(others) for seed in range(3)]
    page = leaderboard_markdown([*results, registered])
    assert page.count(f"Reference conditions `{registered[1]['fingerprint'][:12]}`") == 1
    assert "| 1 | ours | tactile | 1 |" in page.split("### Under other conditions")[0]
    apart = page.split("### Under other conditions")[1]
    assert "start_seed: 0 -> 1" in apart and 'world.backend: "dataset" -> "render"' in apart
    assert "max_episode_steps: 25 -> 30" in apart
    # Where no result holds the registered conditions: the most held of the others, the lowest on a tie.
    fallback = min(r["fingerprint"] for r in others)
    assert f"Reference conditions `{fallback[:12]}`" in leaderboard_markdown(results)


def test_the_leaderboard_ranks_within_the_official_budget_and_lists_the_rest_apart(arrows):
    """DiscreteArrows' budget is 6,250 environment steps: a method trained longer (or of no stated
    budget) is listed apart, never ranked above the methods that kept to it."""
    oracle = evaluate_policy(lambda o: oracle_action(arrows), ARROWS, env=arrows)
    long = make_result(oracle, method="pose oracle, trained long", seed=0, env_steps=6_251)
    unstated = make_result(oracle, method="pose oracle, budget unstated", seed=0)
    page = leaderboard_markdown([("a.json", long), ("b.json", unstated), ("c.json", _result(arrows, seed=0))])
    ranked, over = page.split("### Over the official budget")
    assert "6,250 environment steps (25 epochs of 250)" in ranked
    assert "| 1 | press at once | tactile | 1 |" in ranked and "oracle" not in ranked
    assert "| pose oracle, trained long | tactile | 1 | 1.000 |" in over and "budget unstated" in over


def test_a_searched_method_states_its_trials_and_the_page_compares_the_best(arrows, tmp_path):
    oracle = evaluate_policy(lambda o: oracle_action(arrows), ARROWS, env=arrows)
    ours = [(f"o{seed}.json", make_result(oracle, method="tactile_braille oracle", seed=seed, env_steps=0))
            for seed in range(3)]  # fmt: skip
    pressing = evaluate_policy(press, ARROWS, env=arrows)
    tuned = [(f"t{seed}.json", make_result(pressing, method="SB3 press", seed=seed, env_steps=0,
                                           tuning={"trials": 12})) for seed in range(3)]  # fmt: skip
    page = leaderboard_markdown([*ours, *tuned])
    assert (
        "| 2 | SB3 press | tactile | 3 | 0.177 [0.177, 0.177] | 768 [768, 768] | 237 | 0 | 12 trials |"
        in page
    )
    assert (
        "probability of improvement, ours (`tactile`) over the best other method: 1.00 [1.00, 1.00]" in page
    )
    assert read_result(write_result(tuned[0][1], tmp_path / "t.json"))["tuning"] == {"trials": 12}


def test_the_headline_table_takes_the_best_of_the_paper_ours_per_track_and_the_others(arrows, tmp_path):
    """One row per task: the paper's best row, our best per track (methods of this project's runs), and
    the best other method, ranked as on the leaderboard; written between a page's markers only."""
    oracle = evaluate_policy(lambda o: oracle_action(arrows), ARROWS, env=arrows)
    results = [
        ("a.json", make_result(oracle, method="tactile_braille DQN + HER (`fast`)", seed=0, env_steps=0)),
        ("b.json", _result(arrows, method="tactile_braille DQN + HER (`paper`)", seed=0)),
        ("c.json", _result(arrows, method="SB3 DQN + HER", seed=0)),
        ("d.json", _result(arrows, method="SB3 DQN + HER", seed=1)),
    ]
    table = headline_markdown(results)
    (row,) = [line for line in table.splitlines() if line.startswith("| DiscreteArrows-v0 |")]
    paper, tactile, proprio, other = (cell.strip() for cell in row.split("|")[2:6])
    assert paper == "1.000 in 230 steps (DQN)"  # the better of the paper's DQN and SAC_DISC rows
    assert tactile.startswith("1.000 in ") and tactile.endswith("(DQN + HER (`fast`), 1 seed)")
    assert proprio == "-" and other.endswith("(SB3 DQN + HER, 2 seeds)")
    page = tmp_path / "README.md"
    start, end = HEADLINE_MARKERS
    page.write_text(f"intro\n{start}\nold table\n{end}\noutro\n")
    write_headline(page, table)
    assert page.read_text() == f"intro\n{start}\n{table}{end}\noutro\n"
    page.write_text("no markers\n")
    with pytest.raises(ValueError, match=r"needs the lines .* once each"):
        write_headline(page, table)
    assert page.read_text() == "no markers\n"


def test_the_leaderboard_names_the_released_simulators_rules_of_a_world(continuous, env_datasets):
    released = gym.make(CONTINUOUS, dataset=env_datasets[CONTINUOUS], edges="overrun", tap_depth="released")
    results = [
        (f"{name}.json", make_result(evaluate_policy(lambda o: np.zeros(3, np.float32), CONTINUOUS, env=env,
                                                     sentences=False), method=name, seed=0, env_steps=0))
        for name, env in (("ours", continuous), ("released", released))
    ]  # fmt: skip
    assert results[0][1]["fingerprint"] != results[1][1]["fingerprint"]  # two worlds, never ranked together
    # Unasked, the reference is the default world's, though the released world's seeds outnumber it.
    more = [(f"released{seed}.json", _with_seed(results[1][1], seed)) for seed in (1, 2)]
    page = leaderboard_markdown([*results, *more])
    assert "| 1 | ours | tactile | 1 |" in page.split("### Under other conditions")[0]
    assert "| released | tactile | 3 |" in page.split("### Under other conditions")[1]
    page = leaderboard_markdown(results, reference={"ContinuousArrows-v0": results[1][1]["fingerprint"]})
    assert "(edges `overrun`, tap_depth `released`)" in page.split("### ")[0]
    assert 'world.edges: null -> "overrun"' not in page  # ours is apart, from the released reference:
    assert '"overrun" -> null' in page.split("### Under other conditions")[1]


# ---------------------------------------------------------------- the command
POLICIES = """
def press(observation):
    return 4

def floats(observation):
    return 0.5

def nothing(observation):
    return None

count = 3
"""


def test_cli_scores_a_callable_and_ranks_it(env_datasets, tmp_path, capsys):
    module = tmp_path / "mine.py"
    module.write_text(POLICIES)
    output = tmp_path / "results" / "press.json"
    argv = ["evaluate", "DiscreteArrows-v0", "--policy", f"{module}:press", "--method", "always press",
            "--dataset", str(env_datasets[ARROWS]), "--output", str(output), "--env-steps", "0"]  # fmt: skip
    assert main(argv) == 0
    assert f"wrote {output}" in capsys.readouterr().out
    result = read_result(output)
    assert result["method"] == "always press" and result["budget"] == {"env_steps": 0, "epochs": None}
    assert main(argv) == 2 and "exists; choose another name or pass --overwrite" in capsys.readouterr().err
    page = tmp_path / "board.md"
    assert main(["leaderboard", str(output), "--output", str(page)]) == 0
    assert "| 1 | always press | tactile | 1 |" in page.read_text()
    # The performance profiles: drawn, and linked from the page relative to it.
    figure = tmp_path / "images" / "profiles.png"
    assert main(["leaderboard", str(output), "--output", str(page), "--figure", str(figure)]) == 0
    assert figure.read_bytes().startswith(b"\x89PNG") and "![performance profiles](images/profiles.png)" in (
        page.read_text()
    )
    for bad in (["--figure", str(figure)], ["--output", str(page), "--figure", str(tmp_path)]):
        assert main(["leaderboard", str(output), *bad]) == 2
        assert "--figure" in capsys.readouterr().err


@pytest.mark.parametrize(
    ("policy", "target", "message"),
    [
        ("{module}:floats", "DiscreteArrows-v0", "takes one integer"),
        ("{module}:nothing", "DiscreteArrows-v0", "returned None for DiscreteArrows-v0, not an action"),
        ("{module}:count", "DiscreteArrows-v0", "is a int, not a callable"),
        ("{module}:missing", "DiscreteArrows-v0", "has no 'missing'"),
        ("{module}", "DiscreteArrows-v0", "a policy is MODULE:NAME"),
        ("no_such_module_here:f", "DiscreteArrows-v0", "cannot import the policy's module"),
        ("{module}:press", "Typing-v0", "unknown task 'Typing-v0'"),
    ],
)
def test_cli_refuses_bad_policies_in_one_line(env_datasets, tmp_path, capsys, policy, target, message):
    module = tmp_path / "mine.py"
    module.write_text(POLICIES)
    argv = ["evaluate", target, "--policy", policy.format(module=module), "--method", "m",
            "--dataset", str(env_datasets[ARROWS]), "--output", str(tmp_path / "r.json")]  # fmt: skip
    assert main(argv) == 2
    error = capsys.readouterr().err
    assert message in error and error.count("\n") == 1 and "Traceback" not in error
    assert not (tmp_path / "r.json").exists()


def test_cli_leaderboard_refuses_what_is_not_a_result(tmp_path, capsys):
    (tmp_path / "other.json").write_text("[]")
    assert main(["leaderboard", str(tmp_path / "other.json")]) == 2
    assert "is not a results file of format" in capsys.readouterr().err
    assert main(["leaderboard", str(tmp_path)]) == 2
    assert "is a folder but not a run or a record" in capsys.readouterr().err
    assert load_results([]) == []


def test_a_runs_method_names_each_setting_it_changed_in_its_preset():
    alphabet = "tactile_braille/DiscreteAlphabet-v0"
    assert run_method(preset_config("paper", alphabet, "dqn")) == "tactile_braille DQN + HER (`paper`)"
    # Epochs, seeds and machine settings make no other method; a changed learning setting does.
    assert run_method(preset_config("paper", alphabet, "dqn", epochs=40, seed=3, precision="bf16")) == (
        "tactile_braille DQN + HER (`paper`)"
    )
    changed = preset_config("paper", alphabet, "dqn", replay={"relabel": "all"}, agent={"gamma": 0.9})
    assert run_method(changed) == "tactile_braille DQN + HER (`paper`, agent.gamma=0.9, replay.relabel=all)"


def test_every_committed_results_file_names_the_method_its_settings_ran():
    files = sorted(ROOT.glob("results/**/result.json"))
    recorded = [file for file in files if (file.parent / "config.json").exists()]
    assert recorded, "the repository commits run records with results files"
    for file in recorded:
        config = TrainConfig.from_json(json.loads((file.parent / "config.json").read_text()))
        tuned = (file.parent / "tuning.json").exists()  # a search chose its settings
        assert read_result(file)["method"] == run_method(config, tuned=tuned), file
        assert ("tuning" in read_result(file)) == tuned, file
