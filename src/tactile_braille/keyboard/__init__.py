"""The braille keyboard: layout, braille relief, surface height field and switch model."""

from tactile_braille.keyboard.braille import BRAILLE_DOTS, BrailleGeometry
from tactile_braille.keyboard.layout import (
    ALL_TASK_KEYS,
    ALPHABET_KEYS,
    ARROW_KEYS,
    NONE_KEY,
    Key,
    KeyboardLayout,
    key_set,
)
from tactile_braille.keyboard.surface import KeyboardSurface, KeycapProfile
from tactile_braille.keyboard.switch import SwitchModel

__all__ = [
    "ALL_TASK_KEYS",
    "ALPHABET_KEYS",
    "ARROW_KEYS",
    "BRAILLE_DOTS",
    "NONE_KEY",
    "BrailleGeometry",
    "Key",
    "KeyboardLayout",
    "KeyboardSurface",
    "KeycapProfile",
    "SwitchModel",
    "key_set",
]
