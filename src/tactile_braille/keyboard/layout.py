"""The 84-key keyboard of the paper's rig as data: key names, rows and centres.

The rig used a DREVO Excalibur 84, an ANSI "75 %" layout. Key centres are
given in the **keyboard frame** (millimetres), which is the work frame of the
paper's discrete alphabet task:

* origin at the centre of the Q key top,
* ``x`` across the rows, growing towards the typist (Q row ``x = 0``,
  A row ``x = 19``, Z row ``x = 38``, space-bar row ``x = 57``),
* ``y`` along the rows, growing to the typist's left (Q ``y = 0``,
  P ``y = -171``).

Centres follow from the standard key unit (1 u = 19.05 mm nominal; the rig's
code and this model use 19 mm) and the ANSI key widths, which reproduce the
centres listed in the paper's released code: the arrow block UP (38, -237.5),
DOWN (57, -237.5), LEFT (57, -218.5), RIGHT (57, -256.5) exactly, and SPACE at
(57, -92.625), which the code rounds to (57, -92.5). The released code
rounds the row stagger of the A and Z rows to 5 and 14 mm; the ANSI widths
give 4.75 and 14.25 mm, which is what this model uses.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np

from tactile_braille._tasks import KEY_SETS

KEY_PITCH_MM = 19.0
"""Distance between neighbouring key centres (1 key unit)."""

ARROW_KEYS: tuple[str, ...] = KEY_SETS["arrows"].keys
"""Key set of the arrow tasks: UP, DOWN, LEFT, RIGHT (each key set is a row of
:data:`~tactile_braille._tasks.KEY_SETS`)."""

ALPHABET_KEYS: tuple[str, ...] = KEY_SETS["alphabet"].keys
"""Key set of the alphabet tasks: A-Z plus SPACE (27 keys)."""

ALL_TASK_KEYS: tuple[str, ...] = ALPHABET_KEYS + ARROW_KEYS
"""The 31 keys of the supervised check (alphabet + space + arrows)."""

NONE_KEY = "NONE"
"""Label of a tap that actuated no key (or of a tap off the keys)."""

# Rows of the 75 % ANSI layout, top (F-keys) to bottom, as (name, width in key units).
# The Q row is row 2; the row index fixes x, the running sum of widths fixes y.
_ROWS: tuple[tuple[tuple[str, float], ...], ...] = (
    (("ESC", 1), *((f"F{i}", 1) for i in range(1, 13)), ("PRTSC", 1), ("PAUSE", 1), ("DEL", 1)),
    (("GRAVE", 1), *((str(i), 1) for i in (*range(1, 10), 0)), ("MINUS", 1), ("EQUAL", 1),
     ("BACKSPACE", 2), ("HOME", 1)),
    (("TAB", 1.5), *((c, 1) for c in "QWERTYUIOP"), ("LEFTBRACE", 1), ("RIGHTBRACE", 1),
     ("BACKSLASH", 1.5), ("PAGEUP", 1)),
    (("CAPSLOCK", 1.75), *((c, 1) for c in "ASDFGHJKL"), ("SEMICOLON", 1), ("APOSTROPHE", 1),
     ("ENTER", 2.25), ("PAGEDOWN", 1)),
    (("LEFTSHIFT", 2.25), *((c, 1) for c in "ZXCVBNM"), ("COMMA", 1), ("DOT", 1), ("SLASH", 1),
     ("RIGHTSHIFT", 1.75), ("UP", 1), ("END", 1)),
    (("LEFTCTRL", 1.25), ("LEFTMETA", 1.25), ("LEFTALT", 1.25), ("SPACE", 6.25),
     ("RIGHTALT", 1), ("FN", 1), ("RIGHTCTRL", 1), ("LEFT", 1), ("DOWN", 1), ("RIGHT", 1)),
)  # fmt: skip
_Q_ROW = 2
_Q_CENTRE_U = 2.0  # TAB (1.5 u) + half a key


@dataclass(frozen=True)
class Key:
    """One key of the keyboard.

    Attributes:
        name: evdev-style name without the ``KEY_`` prefix (``"Q"``, ``"SPACE"``).
        index: position in :attr:`KeyboardLayout.keys`.
        row: 0 (function keys) to 5 (space-bar row).
        centre_x_mm: centre across the rows, keyboard frame.
        centre_y_mm: centre along the row, keyboard frame.
        width_u: width along the row in key units (SPACE is 6.25).
    """

    name: str
    index: int
    row: int
    centre_x_mm: float
    centre_y_mm: float
    width_u: float

    @property
    def footprint_mm(self) -> tuple[float, float]:
        """Size of the key's cell (x, y), keycap plus its share of the gap."""
        return KEY_PITCH_MM, self.width_u * KEY_PITCH_MM


class KeyboardLayout:
    """Key centres of the 84-key layout, with look-ups by name.

    Args:
        pitch_mm: key unit; 19 mm as in the paper's code.
    """

    def __init__(self, pitch_mm: float = KEY_PITCH_MM) -> None:
        if not pitch_mm > 0:
            raise ValueError(f"pitch_mm must be positive, got {pitch_mm!r}")
        self.pitch_mm = float(pitch_mm)
        keys: list[Key] = []
        for row, row_keys in enumerate(_ROWS):
            left_edge_u = 0.0
            for name, width_u in row_keys:
                centre_u = left_edge_u + width_u / 2
                keys.append(
                    Key(
                        name=name,
                        index=len(keys),
                        row=row,
                        centre_x_mm=(row - _Q_ROW) * pitch_mm,
                        centre_y_mm=-(centre_u - _Q_CENTRE_U) * pitch_mm,
                        width_u=float(width_u),
                    )
                )
                left_edge_u += width_u
        self.keys: tuple[Key, ...] = tuple(keys)
        self._by_name = {key.name: key for key in self.keys}

    def __len__(self) -> int:
        return len(self.keys)

    def __contains__(self, name: object) -> bool:
        return name in self._by_name

    def key(self, name: str) -> Key:
        """The key called ``name``; raises ``KeyError`` listing valid names."""
        try:
            return self._by_name[name]
        except KeyError:
            raise KeyError(f"unknown key {name!r}; valid keys: {', '.join(self._by_name)}") from None

    def centre_mm(self, name: str) -> tuple[float, float]:
        """Centre (x, y) of key ``name`` in the keyboard frame."""
        key = self.key(name)
        return key.centre_x_mm, key.centre_y_mm

    @cached_property
    def centres_mm(self) -> np.ndarray:
        """(n_keys, 2) array of all key centres, in :attr:`keys` order."""
        return np.array([(k.centre_x_mm, k.centre_y_mm) for k in self.keys])

    @cached_property
    def widths_u(self) -> np.ndarray:
        """(n_keys,) widths along the row in key units."""
        return np.array([k.width_u for k in self.keys])

    @cached_property
    def bounds_mm(self) -> tuple[float, float, float, float]:
        """(x_min, x_max, y_min, y_max) of the keyboard's key cells."""
        half_x = self.pitch_mm / 2
        half_y = self.widths_u * self.pitch_mm / 2
        c = self.centres_mm
        return (
            float(c[:, 0].min() - half_x),
            float(c[:, 0].max() + half_x),
            float((c[:, 1] - half_y).min()),
            float((c[:, 1] + half_y).max()),
        )


def key_set(name: str) -> tuple[str, ...]:
    """The task key set called ``name`` (``"arrows"``, ``"alphabet"`` or ``"all"``)."""
    sets = {"arrows": ARROW_KEYS, "alphabet": ALPHABET_KEYS, "all": ALL_TASK_KEYS}
    try:
        return sets[name]
    except KeyError:
        raise ValueError(f"unknown key set {name!r}; choose one of {sorted(sets)}") from None
