"""Shared fixtures: building a surface raster, a sensor or small datasets once keeps the suite fast.

Every module runs with the default-dataset cache pointed at a temporary folder,
so no test reads or writes the user's cache.

The test modules sit in folders that mirror the package (tests/agents/ for
``tactile_braille.agents``, tests/keyboard/ for ``tactile_braille.keyboard``...),
with no ``__init__.py``: pytest imports each module by its file name, so file
names must be unique across tests/ (hence datasets/test_datasets_cli.py beside
test_cli.py). Helper modules imported by name (toys, envs_helpers,
conftest_datasets, replay_helpers, agents_helpers, feature_agents,
_replay_before) live here in tests/, which pytest puts on sys.path.
"""

from __future__ import annotations

from pathlib import Path

import pytest
import torch

from tactile_braille.datasets import GridTaps, PerturbedTaps, collect
from tactile_braille.keyboard.layout import KeyboardLayout
from tactile_braille.keyboard.surface import KeyboardSurface
from tactile_braille.keyboard.switch import SwitchModel
from tactile_braille.rigs.virtual import VirtualRig
from tactile_braille.sensor.config import sensor_preset
from tactile_braille.sensor.tactip import TacTip


@pytest.fixture(scope="session")
def layout() -> KeyboardLayout:
    return KeyboardLayout()


@pytest.fixture(scope="session")
def switch() -> SwitchModel:
    return SwitchModel()


@pytest.fixture(scope="session")
def surface(layout: KeyboardLayout) -> KeyboardSurface:
    return KeyboardSurface(layout)


@pytest.fixture(scope="session")
def tactip() -> TacTip:
    return TacTip(sensor_preset("braille_331"))


# ------------------------------------------------------------------ environments
@pytest.fixture
def one_torch_thread():
    """Torch on one thread for the test (learning tests stay comparable on a busy machine)."""
    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(threads)


@pytest.fixture(scope="module", autouse=True)
def _cache_in_tmp(tmp_path_factory):
    """Point the default-dataset cache at a session-wide temporary folder while a module runs."""
    folder = tmp_path_factory.getbasetemp() / "tactile_braille_cache"
    folder.mkdir(exist_ok=True)
    with pytest.MonkeyPatch.context() as patch:
        patch.setenv("TACTILE_BRAILLE_DATA", str(folder))
        yield folder


def _collect_once(tmp_path_factory, name: str, procedure) -> Path:
    """Collect ``procedure`` on the virtual rig into a session-wide folder (once per session)."""
    folder = tmp_path_factory.getbasetemp() / "tactile_braille_env_datasets"
    folder.mkdir(exist_ok=True)
    path = folder / f"{name}.h5"
    if not path.exists():
        collect(VirtualRig(seed=0), procedure, path, seed=0, progress=False)
    return path


@pytest.fixture(scope="session")
def env_datasets(tmp_path_factory) -> dict[str, Path]:
    """Small datasets keyed by env id: 3 perturbed taps per key, coarse grids (3 depths)."""
    perturbed = _collect_once(tmp_path_factory, "perturbed-all-3", PerturbedTaps(keys="all", per_key=3))
    arrows = _collect_once(
        tmp_path_factory, "grid-arrows-4mm", GridTaps(keys="arrows", spacing_mm=4, depth_step_mm=3)
    )
    alphabet = _collect_once(
        tmp_path_factory, "grid-alphabet-6mm", GridTaps(keys="alphabet", spacing_mm=6, depth_step_mm=3)
    )
    return {
        "tactile_braille/DiscreteArrows-v0": perturbed,
        "tactile_braille/DiscreteAlphabet-v0": perturbed,
        "tactile_braille/ContinuousArrows-v0": arrows,
        "tactile_braille/ContinuousAlphabet-v0": alphabet,
    }
