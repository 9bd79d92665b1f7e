"""`tactile-braille train` exposes every setting of a run, and refuses bad ones before writing anything."""

from __future__ import annotations

import contextlib
import dataclasses
import types
import typing
from typing import Literal

import pytest

from tactile_braille.agents.config import GROUPS, TrainConfig, flatten
from tactile_braille.agents.registry import agent_names, agent_spec
from tactile_braille.cli import _train_config, build_parser, main
from tactile_braille.cli_config import POSITIONAL, RECORD_ONLY

TASKS = {"dqn": "DiscreteArrows-v0", "sac_discrete": "DiscreteArrows-v0", "planner": "DiscreteArrows-v0",
         "sac": "ContinuousArrows-v0", "td3": "ContinuousArrows-v0", "mrq": "DiscreteArrows-v0"}  # fmt: skip


def _settings(algo: str) -> dict[str, tuple[type, object]]:
    """dotted name -> (annotation, default) of every setting a run of ``algo`` has."""
    found = {}
    for cls, prefix in ((TrainConfig, ""), *((group, f"{name}.") for name, group in GROUPS.items()),
                        (agent_spec(algo).config, "agent.")):  # fmt: skip
        hints = typing.get_type_hints(cls)
        for spec in dataclasses.fields(cls):
            if spec.name in ("agent", *GROUPS) and cls is TrainConfig:
                continue
            default = spec.default if spec.default is not dataclasses.MISSING else spec.default_factory()
            found[prefix + spec.name] = (hints[spec.name], default)
    return found


def _other_value(hint, default):
    """A value of the setting's type that differs from its default, and its command-line words."""
    args = [a for a in typing.get_args(hint) if a is not type(None)]
    base = args[0] if typing.get_origin(hint) in (typing.Union, types.UnionType) else hint
    if typing.get_origin(base) is Literal:
        value = next(choice for choice in reversed(typing.get_args(base)) if choice != default)
        return value, [value]
    if typing.get_origin(base) is tuple:
        return (7, 8), ["7", "8"]
    if base is bool:
        return (not default), None
    if base is int:
        return 3, ["3"]
    if base is float:
        return 0.5, ["0.5"]
    return "cuda:1", ["cuda:1"]  # the one free string besides the dataset path, checked by the config


@pytest.mark.parametrize("algo", agent_names())
def test_every_setting_of_a_run_can_be_set_from_the_command_line(algo):
    argv, wanted = ["train", TASKS[algo], algo], {}
    for name, (hint, default) in _settings(algo).items():
        if name in (*POSITIONAL, *RECORD_ONLY):
            continue
        if algo == "planner" and name.startswith("touch."):  # it reads images itself (test_planner)
            continue
        value, words = _other_value(hint, default)
        if name == "dataset":
            value, words = "elsewhere.h5", ["elsewhere.h5"]
        if name == "start_steps":  # a touch encoder needs at least 10 (refused otherwise, tested below)
            value, words = 30, ["30"]
        if name == "touch.labels":  # pose inputs need the robot's labels (refused otherwise, test_tracks)
            value, words = "robot", ["robot"]
        if name == "backend":  # frame noise needs the live renderer (refused otherwise, test_config)
            value, words = "render", ["render"]
        if name == "frame_noise":
            value, words = (1.0, 2.0), ["1.0", "2.0"]
        if name == "edges" and algo not in ("sac", "td3"):  # the continuous tasks' (test_config)
            value, words = "stop", ["stop"]
        if name == "key_grid" and algo in ("sac", "td3"):  # the discrete tasks' (test_config)
            value, words = "rig", ["rig"]
        if name == "tap_depth":  # given as its default: the released lookup needs the dataset backend
            value, words = "commanded", ["commanded"]
        if name == "taps":  # given as its default: the touch encoder reads one tap (test_config)
            value, words = 1, ["1"]
        if name == "replay.n_step":  # given as its default: all-goals updates refuse n-step returns
            value, words = 1, ["1"]
        if name == "replay.shift":  # given as its default: the touch encoder's features refuse shifts
            value, words = 0, ["0"]
        if name == "agent.image_shift":  # MR.Q's; none, as the touch encoder's features refuse shifts
            value, words = 0, ["0"]
        if name == "agent.goal_difference":  # given as its default: it refuses goal heads (test_algorithms)
            value, words = 0, ["0"]
        if name == "agent.return_bound":  # given as its default: it refuses all-goals updates
            value, words = False, None
        if name == "agent.return_bound_after":  # given as its default: it needs return_bound
            value, words = 0, ["0"]
        if name == "touch.goal_positions":  # given as its default: all-goals updates refuse goal positions
            value, words = False, None
        flag = "--" + name.replace("_", "-")
        argv += [flag, *words] if words is not None else [flag if value else "--no-" + flag[2:]]
        wanted[name] = list(value) if isinstance(value, tuple) else value
    config = _train_config(build_parser().parse_args(argv))
    given = flatten(config)
    assert {name: given[name] for name in wanted} == wanted
    untouched = {name for name in given if name.startswith("touch.")} if algo == "planner" else set()
    assert set(given) - set(wanted) == {*POSITIONAL, *RECORD_ONLY, *untouched}  # every other one given


def test_an_option_given_overrides_the_preset_and_the_rest_stays():
    args = build_parser().parse_args(["train", "ContinuousArrows-v0", "sac", "--preset", "fast",
                                      "--touch.refits", "0", "--agent.hidden", "64"])  # fmt: skip
    config = _train_config(args)
    assert (config.touch.refits, config.agent.hidden) == (0, (64,))
    assert (config.touch.enabled, config.replay.relabel, config.agent.batch_size) == (True, "all", 128)


@pytest.mark.parametrize(
    ("options", "message"),
    [
        (["--backend", "bogus"], "invalid choice: 'bogus'"),
        (["--epochs", "0"], "TrainConfig.epochs must be at least 1"),
        (["--epochs", "1e30"], "invalid int value"),
        (["--device", "gpu"], "device must be cpu, cuda, cuda:N or mps"),
        (["--agent.gamma", "1.5"], "gamma must be in"),
        (["--agent.hidden", "0"], "hidden needs at least one positive layer size"),
        (["--agent.critic-pose"], "--agent.critic-pose is not a setting of dqn"),
        (["--touch.goal-positions"], "set touch.enabled too"),
        (["--touch.enabled", "--start-steps", "5"], "at least 10"),
        (["--simulated-rig", "--backend", "dataset"], "drop --backend dataset"),
    ],
)
def test_a_bad_setting_is_refused_before_the_run_folder_exists(tmp_path, capsys, options, message):
    run = tmp_path / "run"
    with pytest.raises(SystemExit) if "invalid" in message else contextlib.nullcontext():
        code = main(["train", "DiscreteArrows-v0", "dqn", "--run-dir", str(run), *options])
        assert code == 2
    assert message in capsys.readouterr().err
    assert not run.exists()


def test_rig_options_train_on_the_rig():
    args = build_parser().parse_args(["train", "DiscreteArrows-v0", "--simulated-rig"])
    assert _train_config(args).backend == "rig"


def test_the_agent_options_name_the_algorithms_that_take_them(capsys):
    with pytest.raises(SystemExit):
        main(["train", "--help"])
    text = " ".join(capsys.readouterr().out.split())
    assert "--agent.policy-delay" in text and "[td3]" in text
    assert "--touch.refit-every" in text and "'none' for the default" in text
