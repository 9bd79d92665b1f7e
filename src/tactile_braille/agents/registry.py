"""The agents a run can train: one :class:`AgentSpec` per agent, the single place an agent is named.

Everything that lists agents reads this registry: the ``algo`` a
:class:`~tactile_braille.agents.config.TrainConfig` accepts and its
hyperparameter class, the command line's choices and ``--agent.*`` options,
presets, the training loop's agent and replay, and the names reports and the
leaderboard print. Adding an agent is one call, from any module:

>>> from tactile_braille.agents.registry import agent_spec, agent_names
>>> agent_spec("td3").label, sorted(agent_spec("planner").actions)
('TD3', ['continuous', 'discrete'])
>>> "dqn" in agent_names()
True

The registry imports no torch: an agent's class is named as ``"module:Class"``
and imported on first use (or given as the class itself). What an agent class
must provide is :class:`~tactile_braille.agents.common.Agent`'s contract;
what its hyperparameter class must provide is
:class:`~tactile_braille.agents.config.AgentConfig`'s.
``examples/custom_agent.py`` registers and trains an agent of its own.
"""

from __future__ import annotations

import dataclasses
import importlib
import importlib.metadata
import re
from dataclasses import dataclass

from tactile_braille.agents.config import (
    AgentConfig,
    DiscreteSACConfig,
    DQNConfig,
    MRQConfig,
    PlannerConfig,
    SACConfig,
    TD3Config,
)

ACTION_KINDS = ("discrete", "continuous")
"""The action spaces of the braille tasks: ``Discrete(5)`` grid moves and PRESS, or a ``Box`` move."""

_NAME = re.compile(r"[a-z][a-z0-9_]*")


@dataclass(frozen=True)
class AgentSpec:
    """An agent as the project knows it.

    Attributes:
        name: the ``algo`` that selects it (``TrainConfig(algo=...)``, ``tactile-braille train TASK
            NAME``): lower case letters, digits and ``_``; run folders and records carry it.
        config: its hyperparameters, a frozen dataclass subclassing
            :class:`~tactile_braille.agents.config.AgentConfig` whose every field has a default;
            the command line's ``--agent.*`` options are generated from its fields and docstring.
        agent: its class (an :class:`~tactile_braille.agents.common.Agent`), or ``"module:Class"``
            imported when first needed (so that reading settings needs no torch).
        actions: the action kinds it acts in, a subset of :data:`ACTION_KINDS`.
        label: its name in reports and on the leaderboard (``"DQN"``).
        hindsight: whether ``replay.her`` means hindsight relabelling of the goals it learns from
            (the leaderboard then names the method ``... + HER``); False for an agent whose
            learning ignores the goals the replay gives (the key-graph planner).
        updates_per_step: gradient updates per environment step where a run leaves
            ``updates_per_step`` unset.
    """

    name: str
    config: type[AgentConfig]
    agent: type | str
    actions: frozenset[str]
    label: str
    hindsight: bool = True
    updates_per_step: int = 2

    def __post_init__(self) -> None:
        object.__setattr__(self, "actions", frozenset(self.actions))
        problems = []
        if not isinstance(self.name, str) or not _NAME.fullmatch(self.name):
            problems.append(f"name must be lower case letters, digits and '_', got {self.name!r}")
        if not (isinstance(self.config, type) and issubclass(self.config, AgentConfig)):
            problems.append(f"config must be a subclass of AgentConfig, got {self.config!r}")
        elif not dataclasses.is_dataclass(self.config) or not self.config.__dataclass_params__.frozen:
            problems.append(f"config {self.config.__name__} must be a frozen dataclass")
        else:
            try:
                self.config()
            except TypeError as error:
                problems.append(f"config {self.config.__name__} needs a default for every field ({error})")
        if not isinstance(self.agent, type | str) or (isinstance(self.agent, str) and ":" not in self.agent):
            problems.append(f"agent must be a class or 'module:Class', got {self.agent!r}")
        if not self.actions or not self.actions <= set(ACTION_KINDS):
            problems.append(
                f"actions must be a non-empty subset of {ACTION_KINDS}, got {sorted(self.actions)}"
            )
        if not isinstance(self.label, str) or not self.label:
            problems.append(f"label must be a non-empty string, got {self.label!r}")
        if not isinstance(self.updates_per_step, int) or self.updates_per_step < 0:
            problems.append(f"updates_per_step must be a whole number >= 0, got {self.updates_per_step!r}")
        if problems:
            raise ValueError(f"AgentSpec {self.name!r}: " + "; ".join(problems))

    @property
    def agent_class(self) -> type:
        """The agent's class (imported now if it was named as ``"module:Class"``)."""
        if isinstance(self.agent, type):
            return self.agent
        module, _, name = self.agent.partition(":")
        try:
            return getattr(importlib.import_module(module), name)
        except (ImportError, AttributeError) as error:
            raise ImportError(f"agent {self.name!r}: cannot import {self.agent!r} ({error})") from error

    def acts_in(self, continuous: bool) -> bool:
        """Whether it acts in a continuous (True) or a discrete (False) task."""
        return ("continuous" if continuous else "discrete") in self.actions


_REGISTRY: dict[str, AgentSpec] = {}


def register_agent(spec: AgentSpec, replace: bool = False) -> AgentSpec:
    """Make ``spec`` an agent runs can name; returns it.

    Raises:
        ValueError: an agent of that name is registered already (pass ``replace=True`` to swap it
            for another, as a module reloaded in a notebook does).
    """
    if not isinstance(spec, AgentSpec):
        raise TypeError(f"register_agent takes an AgentSpec, got {type(spec).__name__}")
    if spec.name in _REGISTRY and not replace and _REGISTRY[spec.name] != spec:
        raise ValueError(
            f"an agent named {spec.name!r} is registered already; pass replace=True to replace it"
        )
    _REGISTRY[spec.name] = spec
    return spec


def agent_spec(name: str) -> AgentSpec:
    """The registered agent ``name`` (an installed package's agents are loaded first, :data:`ENTRY_POINTS`).

    Raises:
        ValueError: no agent of that name, with the names there are.
    """
    if name not in _REGISTRY:
        load_entry_points()
    try:
        return _REGISTRY[name]
    except (KeyError, TypeError):
        raise ValueError(f"unknown algorithm {name!r}; choose one of {agent_names()}") from None


def agent_names() -> tuple[str, ...]:
    """The registered agents' names, in the order they were registered (an installed package's too)."""
    load_entry_points()
    return tuple(_REGISTRY)


ENTRY_POINTS = "tactile_braille.agents"
"""The entry-point group through which an installed package brings its agents to the command line: each
entry point names a module that registers agents when imported (``pyproject.toml``:
``[project.entry-points."tactile_braille.agents"] my_agent = "my_package.agent"``)."""

_entry_points_loaded = False


def load_entry_points() -> None:
    """Import the modules of the installed packages' :data:`ENTRY_POINTS` (once), so that they register
    their agents; one that fails to import is named in the error."""
    global _entry_points_loaded
    if _entry_points_loaded:
        return
    _entry_points_loaded = True
    for entry in importlib.metadata.entry_points(group=ENTRY_POINTS):
        try:
            entry.load()
        except Exception as error:
            raise ImportError(
                f"the agent entry point {entry.name!r} ({entry.value}) failed: {error}"
            ) from error


def agent_label(name: str) -> str:
    """An agent's name in reports: its spec's label, or ``name`` itself for one not registered here
    (a record of an agent whose module is not imported)."""
    spec = _REGISTRY.get(name)
    return spec.label if spec is not None else name


for _spec in (
    AgentSpec("dqn", DQNConfig, "tactile_braille.agents.dqn:DQNAgent", {"discrete"}, "DQN"),
    AgentSpec("sac_discrete", DiscreteSACConfig, "tactile_braille.agents.sac_discrete:DiscreteSACAgent",
              {"discrete"}, "SAC_DISC"),
    AgentSpec("sac", SACConfig, "tactile_braille.agents.sac:SACAgent", {"continuous"}, "SAC"),
    AgentSpec("td3", TD3Config, "tactile_braille.agents.td3:TD3Agent", {"continuous"}, "TD3",
              updates_per_step=1),
    AgentSpec("planner", PlannerConfig, "tactile_braille.agents.planner:PlannerAgent",
              {"discrete", "continuous"}, "planner", hindsight=False),
    AgentSpec("mrq", MRQConfig, "tactile_braille.agents.mrq:MRQAgent", {"discrete", "continuous"}, "MR.Q",
              updates_per_step=1),
):  # fmt: skip
    register_agent(_spec)
PAPER_AGENTS = ("dqn", "sac_discrete", "sac", "td3")
"""The paper's four agents (its Table III's rows)."""
