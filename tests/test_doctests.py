"""The examples in the package's docstrings run and show what they say (each module's doctests)."""

from __future__ import annotations

import doctest
import importlib
import importlib.util
import pkgutil
from pathlib import Path

import pytest

import tactile_braille


def _modules_with_examples() -> list[str]:
    """The package's modules whose source holds a docstring example (``>>>``), found by their text."""
    names = []
    for module in pkgutil.walk_packages(tactile_braille.__path__, "tactile_braille."):
        origin = importlib.util.find_spec(module.name).origin
        if origin and origin.endswith(".py") and ">>> " in Path(origin).read_text(encoding="utf-8"):
            names.append(module.name)
    return names


MODULES = _modules_with_examples()
SLOW = {
    "tactile_braille.envs.continuous",
    "tactile_braille.envs.discrete",
    "tactile_braille.agents.rollout",
    "tactile_braille.sensor.batched",
}
"""Modules whose examples make environments or render (seconds each): run by ``make test-slow``."""


def test_modules_with_examples_are_found():
    assert {
        "tactile_braille.agents.config",
        "tactile_braille.agents.registry",
        "tactile_braille._tasks",
    } <= set(MODULES)


@pytest.mark.parametrize(
    "name", [pytest.param(n, marks=[pytest.mark.slow] if n in SLOW else []) for n in MODULES]
)
def test_the_docstring_examples_run(name):
    result = doctest.testmod(importlib.import_module(name), optionflags=doctest.ELLIPSIS)
    assert result.failed == 0, f"{result.failed} of {result.attempted} examples of {name} failed (see above)"
