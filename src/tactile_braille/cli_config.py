"""Command-line options generated from the training settings (:mod:`tactile_braille.agents.config`).

Every field of :class:`~tactile_braille.agents.config.TrainConfig` and of its
groups becomes an option: ``--steps-per-epoch 500``, ``--replay.relabel all``,
``--touch.enabled`` / ``--no-touch.enabled``, ``--agent.hidden 256 256``,
``--touch.refit-every none``. Types, accepted values and help come from the
dataclasses' annotations and docstrings, so the command line cannot drift from
the settings. An option given overrides the preset; one not given leaves it.
The ``agent`` options are the union of the registered agents' hyperparameters
(:mod:`~tactile_braille.agents.registry`); one the chosen agent lacks is refused.
"""

from __future__ import annotations

import argparse
import dataclasses
import inspect
import re
import types
import typing
from typing import Any, Literal, Union

from tactile_braille.agents.config import GROUPS, TrainConfig
from tactile_braille.agents.registry import agent_names, agent_spec

PREFIX = "setting:"
"""``argparse`` destinations of generated options start with this, then the dotted setting name."""
POSITIONAL = ("task", "algo")
"""Settings given as positional arguments, not options."""
RECORD_ONLY = ("preset",)
"""Settings a command-line user does not set (``--preset`` chooses the preset and records it)."""
ALIASES = {"evaluation.test_episodes": ("--test-episodes",)}
"""Older option names kept working (``--no-her`` is :data:`ALIASES`' boolean twin, below)."""
AUTO = {
    "precision": "Or auto, the default of a new run: bf16 where the device computes bfloat16 natively (a "
    "CPU with AVX512-BF16 or AMX, a CUDA device that supports it), else fp32; resolved on this machine "
    "before the run's settings are recorded (config.json holds fp32 or bf16; a resume keeps its own).",
}
"""Settings whose option also takes ``auto`` (and its help): chosen on this machine by
:func:`resolve_precision`."""


def field_docs(cls: type) -> dict[str, str]:
    """Each attribute's text in a Google-style ``Attributes:`` docstring section, joined on one line."""
    docs: dict[str, str] = {}
    section = inspect.getdoc(cls).partition("Attributes:")[2]
    for match in re.finditer(r"^ {4}(\w+(?:, \w+)*): (.*?)(?=^ {4}\w+(?:, \w+)*: |\Z)", section, re.M | re.S):
        text = " ".join(match.group(2).split())
        for name in match.group(1).split(","):
            docs[name.strip()] = text
    return docs


def add_config_options(parser: argparse.ArgumentParser, skip: tuple[str, ...] = ()) -> None:
    """Add an option for every setting of a training run (top-level ones, then one group each), but
    the top-level ones in ``skip`` (a command that has options of its own for them)."""
    top = parser.add_argument_group("run settings (override the preset)")
    hints, docs = typing.get_type_hints(TrainConfig), field_docs(TrainConfig)
    for spec in dataclasses.fields(TrainConfig):
        if spec.name in (*POSITIONAL, *RECORD_ONLY, "agent", *GROUPS, *skip):
            continue
        _add_option(top, spec.name, hints[spec.name], docs.get(spec.name, ""))
    for group_name, cls in GROUPS.items():
        group = parser.add_argument_group(f"{group_name} settings ({cls.__name__})")
        hints, docs = typing.get_type_hints(cls), field_docs(cls)
        for spec in dataclasses.fields(cls):
            _add_option(group, f"{group_name}.{spec.name}", hints[spec.name], docs.get(spec.name, ""))
    group = parser.add_argument_group("agent settings (the algorithm's hyperparameters)")
    for name, (hint, doc, owners) in _agent_fields().items():
        takes = "all algorithms" if len(owners) == len(agent_names()) else ", ".join(owners)
        _add_option(group, f"agent.{name}", hint, f"{doc} [{takes}]")
    parser.add_argument(
        "--no-her", dest=PREFIX + "replay.her", action="store_false", default=argparse.SUPPRESS,
        help="same as --no-replay.her",
    )  # fmt: skip


def _agent_fields() -> dict[str, tuple[Any, str, list[str]]]:
    """name -> (annotation, help, algorithms that take it), over the registered agents' hyperparameters."""
    fields: dict[str, tuple[Any, str, list[str]]] = {}
    for algo in agent_names():
        cls = agent_spec(algo).config
        hints, docs = typing.get_type_hints(cls), field_docs(cls)
        for spec in dataclasses.fields(cls):
            hint, doc, owners = fields.get(spec.name, (hints[spec.name], docs.get(spec.name, ""), []))
            fields[spec.name] = (hint, doc, [*owners, algo])
    return fields


def _add_option(group, name: str, hint: Any, doc: str) -> None:
    flags = ["--" + name.replace("_", "-"), *ALIASES.get(name, ())]
    options: dict[str, Any] = {"dest": PREFIX + name, "default": argparse.SUPPRESS, "help": doc}
    optional = typing.get_origin(hint) in (Union, types.UnionType) and type(None) in typing.get_args(hint)
    base = next((a for a in typing.get_args(hint) if a is not type(None)), hint) if optional else hint
    origin = typing.get_origin(base)
    if base is bool:
        options["action"] = argparse.BooleanOptionalAction
    elif origin is Literal:
        options["choices"] = typing.get_args(base) + (("auto",) if name in AUTO else ())
        options["help"] += f" {AUTO[name]}" if name in AUTO else ""
    elif origin is tuple:
        options.update(nargs="+", type=typing.get_args(base)[0], metavar=name.split(".")[-1].upper())
    elif base in (int, float, str):
        options.update(type=base, metavar=name.split(".")[-1].upper())
    else:  # the agent group itself, handled apart
        raise TypeError(f"no command-line form for {name}: {hint}")
    if optional:
        options["type"] = _or_none(options.get("type", str))
        options["help"] += " ('none' for the default)"
    group.add_argument(*flags, **options)


def _or_none(parse):
    def parse_or_none(text: str):
        return None if text.lower() == "none" else parse(text)

    parse_or_none.__name__ = getattr(parse, "__name__", "value")  # argparse names the type in errors
    return parse_or_none


def config_overrides(args: argparse.Namespace, algo: str) -> dict[str, Any]:
    """The settings given on the command line, as :func:`~tactile_braille.agents.config.replace_settings`
    takes them (groups as dicts); an ``--agent.*`` option that ``algo`` has no use for is refused."""
    changes: dict[str, Any] = {}
    for dest, value in vars(args).items():
        if not dest.startswith(PREFIX):
            continue
        *group, name = dest.removeprefix(PREFIX).split(".")
        value = tuple(value) if isinstance(value, list) else value
        if group == ["agent"] and name not in _field_names(algo):
            owners = [other for other in agent_names() if name in _field_names(other)]
            raise ValueError(
                f"--agent.{name.replace('_', '-')} is not a setting of {algo} (only of {', '.join(owners)})"
            )
        if group:
            changes.setdefault(group[0], {})[name] = value
        else:
            changes[name] = value
    return changes


def resolve_precision(precision: str, device: str) -> str:
    """``precision`` as a run records it: ``auto`` is bf16 where ``device`` (a CPU or CUDA device)
    computes bfloat16 natively (:func:`~tactile_braille.agents.common.native_bf16`), else fp32; fp32
    and bf16 stay."""
    if precision != "auto":
        return precision
    from tactile_braille.agents.common import native_bf16  # torch: only once the settings are checked

    known = device.partition(":")[0] in ("cpu", "cuda")  # elsewhere native_bf16 cannot tell
    return "bf16" if known and native_bf16(device) else "fp32"


def _field_names(algo: str) -> set[str]:
    """The names of agent ``algo``'s hyperparameters."""
    return {spec.name for spec in dataclasses.fields(agent_spec(algo).config)}
