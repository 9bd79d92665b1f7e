"""Shared, session-scoped fixtures: building a surface raster or a sensor once keeps the suite fast."""

from __future__ import annotations

import pytest

from tactile_braille.keyboard.layout import KeyboardLayout
from tactile_braille.keyboard.surface import KeyboardSurface
from tactile_braille.keyboard.switch import SwitchModel
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
