"""The agent registry: one entry per agent, which settings, the command line, presets and reports read."""

from __future__ import annotations

from dataclasses import dataclass

import pytest

from tactile_braille.agents import registry
from tactile_braille.agents.common import Agent
from tactile_braille.agents.config import AgentConfig, DQNConfig, TrainConfig
from tactile_braille.agents.registry import AgentSpec, agent_label, agent_names, agent_spec, register_agent
from tactile_braille.cli import build_parser


@pytest.fixture
def scratch_registry(monkeypatch):
    """A copy of the registry for one test: what it registers is gone after it."""
    monkeypatch.setattr(registry, "_REGISTRY", dict(registry._REGISTRY))


@dataclass(frozen=True)
class TinyConfig(AgentConfig):
    """Attributes:
    gamma: discount.
    batch_size: transitions per update.
    spread: a setting of its own.
    """

    gamma: float = 0.9
    batch_size: int = 4
    spread: float = 1.0


def test_the_projects_agents_are_registered_with_their_kinds_labels_and_loaders():
    assert agent_names() == ("dqn", "sac_discrete", "sac", "td3", "planner", "mrq")
    kinds = {name: sorted(agent_spec(name).actions) for name in agent_names()}
    assert kinds["dqn"] == kinds["sac_discrete"] == ["discrete"]
    assert kinds["sac"] == kinds["td3"] == ["continuous"]
    assert kinds["planner"] == kinds["mrq"] == ["continuous", "discrete"]
    labels = [agent_label(name) for name in agent_names()]
    assert labels == ["DQN", "SAC_DISC", "SAC", "TD3", "planner", "MR.Q"]
    for name in agent_names():
        agent_class = agent_spec(name).agent_class
        assert issubclass(agent_class, Agent) and agent_class.__name__.endswith("Agent")
    assert not agent_spec("planner").hindsight and agent_spec("dqn").hindsight
    assert TrainConfig(algo="td3", task="tactile_braille/ContinuousArrows-v0").updates_per_step == 1
    assert agent_label("not_registered") == "not_registered"  # a record of an agent not imported


def test_an_unknown_agent_is_refused_with_the_registered_names():
    with pytest.raises(ValueError, match=r"unknown algorithm 'dq'; choose one of \('dqn', "):
        agent_spec("dq")
    with pytest.raises(ValueError, match="unknown algorithm 'dq'"):
        TrainConfig(algo="dq")


@pytest.mark.parametrize(
    ("changes", "problem"),
    [
        ({"name": "Tiny-Agent"}, "name must be lower case"),
        ({"config": DQNConfig.__mro__[-1]}, "config must be a subclass of AgentConfig"),
        ({"agent": "no_colon"}, "agent must be a class or 'module:Class'"),
        ({"actions": {"analogue"}}, "actions must be a non-empty subset"),
        ({"actions": set()}, "actions must be a non-empty subset"),
        ({"label": ""}, "label must be a non-empty string"),
        ({"updates_per_step": -1}, "updates_per_step must be a whole number"),
    ],
)
def test_a_bad_spec_is_refused_naming_what_is_wrong(changes, problem):
    spec = {"name": "tiny", "config": TinyConfig, "agent": "mypackage:TinyAgent", "actions": {"discrete"},
            "label": "Tiny", **changes}  # fmt: skip
    with pytest.raises(ValueError, match=problem):
        AgentSpec(**spec)


def test_a_config_without_defaults_is_refused():
    @dataclass(frozen=True)
    class Undefaulted(AgentConfig):
        gamma: float

    with pytest.raises(ValueError, match="needs a default for every field"):
        AgentSpec("tiny", Undefaulted, "mypackage:TinyAgent", {"discrete"}, "Tiny")


def test_a_registered_agent_is_a_run_setting_a_cli_choice_and_an_option_source(scratch_registry):
    register_agent(AgentSpec("tiny", TinyConfig, "mypackage.agents:TinyAgent", {"discrete"}, "Tiny"))
    config = TrainConfig(algo="tiny", agent={"spread": 2.0})
    assert config.agent == TinyConfig(spread=2.0) and config.updates_per_step == 2
    assert TrainConfig.from_json(config.to_json()) == config  # records read back
    with pytest.raises(ValueError, match=r"TinyConfig has no settings \['hidden'\]"):
        TrainConfig(algo="tiny", agent={"hidden": (8,)})
    with pytest.raises(ValueError, match=r"TinyConfig: gamma must be in \[0, 1\], got 2.0"):
        TinyConfig(gamma=2.0)  # the usual ranges, from the base class
    args = build_parser().parse_args(["train", "DiscreteArrows-v0", "tiny", "--agent.spread", "3"])
    assert args.algo == "tiny"
    with pytest.raises(ImportError, match=r"cannot import 'mypackage\.agents:TinyAgent'"):
        agent_spec("tiny").agent_class  # noqa: B018 - imported on first use, and named when it fails


def test_a_name_is_registered_once_unless_replaced(scratch_registry):
    spec = AgentSpec("tiny", TinyConfig, "mypackage:TinyAgent", {"discrete"}, "Tiny")
    register_agent(spec)
    register_agent(spec)  # the same entry again is harmless
    other = AgentSpec("tiny", TinyConfig, "mypackage:TinyAgent", {"continuous"}, "Tiny")
    with pytest.raises(ValueError, match="registered already; pass replace=True"):
        register_agent(other)
    assert register_agent(other, replace=True) is other and agent_spec("tiny").actions == {"continuous"}
    with pytest.raises(TypeError, match="takes an AgentSpec"):
        register_agent({"name": "tiny"})


def test_an_agent_without_policy_action_or_update_cannot_be_made():
    class Incomplete(Agent):
        def update(self, batch):
            return {}

    with pytest.raises(TypeError, match="policy_action"):
        Incomplete("cpu", "fp32")


def test_an_installed_package_brings_its_agents_through_an_entry_point(
    scratch_registry, tmp_path, monkeypatch
):
    """A distribution on the path whose ``tactile_braille.agents`` entry point names a module that registers
    an agent: the command line and the settings know the agent without anyone importing it."""
    info = tmp_path / "tiny_plugin-1.0.dist-info"
    info.mkdir()
    (info / "METADATA").write_text("Metadata-Version: 2.1\nName: tiny-plugin\nVersion: 1.0\n")
    (info / "entry_points.txt").write_text("[tactile_braille.agents]\ntiny = tiny_plugin_agent\n")
    (tmp_path / "tiny_plugin_agent.py").write_text(
        "from tactile_braille.agents.registry import AgentSpec, register_agent\n"
        "from tactile_braille.agents.config import PlannerConfig\n"
        "register_agent(AgentSpec('tiny_plugin', PlannerConfig, 'tiny_plugin_agent:Agent', {'discrete'},\n"
        "                         'Tiny'))\n"
    )
    monkeypatch.syspath_prepend(str(tmp_path))
    monkeypatch.setattr(registry, "_entry_points_loaded", False)
    assert agent_spec("tiny_plugin").label == "Tiny"
    assert "tiny_plugin" in agent_names()
    (tmp_path / "tiny_plugin_agent.py").write_text("raise RuntimeError('broken plugin')\n")
    monkeypatch.delitem(__import__("sys").modules, "tiny_plugin_agent")
    monkeypatch.setattr(registry, "_entry_points_loaded", False)
    with pytest.raises(
        ImportError, match=r"agent entry point 'tiny' \(tiny_plugin_agent\) failed: broken plugin"
    ):
        agent_names()
