"""Which key, if any, actuates when the sensor taps the keyboard.

A tap drives the apex of the sensor's soft dome ``depth_mm`` below the work
frame origin, which sits ``clearance_mm`` above the key tops. A Cherry MX
Black switch is linear: the key registers once its top has been pushed down
by its pre-travel, and pushing it takes the dome's own compression on top.

The model, fitted to the real robot's activation maps
(:mod:`tactile_braille.keyboard.calibration`), has three parts:

* **Dome geometry.** The dome is a spherical cap of radius
  ``dome_radius_mm``. When its apex is over the key's flat top it meets the
  key there; otherwise it meets the top's nearest edge, at horizontal distance
  ``r``, which lies ``R - sqrt(R^2 - r^2)`` above the apex: the sensor must go
  that much deeper first. The membrane is also softer when it meets the key
  obliquely (at angle ``theta``, ``sin(theta) = r / R``), which
  ``compliance_mm * (1 / cos(theta) - 1)`` accounts for (the fit makes it
  negative: the flank of the dome, pressed sideways against the key's edge,
  bulges down into it).
* **Keycap rocking.** A keycap pushed off its stem tilts instead of sliding
  straight down, so the contact point must travel further:
  ``rocking_x * |e_x|^p + rocking_y * |e_y|^p`` for a contact point at
  ``(e_x, e_y)`` from the key centre. Keys wider than 1 u (SPACE) are held
  level by a stabiliser bar over ``stabiliser_fraction`` of their extra width.
* **Switch tolerance.** Each switch registers at its own pre-travel: Cherry
  specifies 2.0 +/- 0.6 mm for MX switches. ``travel_offsets_mm`` lowers
  (positive) or raises (negative) one key's actuation travel; the fit to the
  alphabet map gives offsets within +/- 0.5 mm. They move the depth at which a
  key's footprint opens, not its centre or shape.
* **Actuation.** The key with the largest margin (penetration minus the
  travel required) registers when that margin is non-negative.

This reproduces what the real rig recorded: no press at shallow taps, and a
footprint of actuating positions that grows with depth from a patch around
the key centre to nearly the whole key, with diamond-shaped tips between
rows. The defaults are the joint fit to both of the original release's maps.
"""

from __future__ import annotations

import functools
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from tactile_braille.keyboard.layout import KeyboardLayout

SWITCH_TOLERANCE_MM = 0.6
"""Pre-travel tolerance of a Cherry MX switch (2.0 +/- 0.6 mm)."""

FITTED_TRAVEL_OFFSETS_MM: tuple[tuple[str, float], ...] = (
    ("A", -0.35), ("C", -0.4), ("D", -0.45), ("E", -0.3), ("F", 0.1), ("G", -0.2), ("H", -0.15),
    ("I", 0.05), ("J", 0.05), ("K", -0.3), ("M", 0.1), ("O", 0.25), ("P", 0.15), ("Q", 0.25),
    ("S", 0.2), ("SPACE", -0.05), ("T", -0.45), ("U", -0.3), ("V", 0.2), ("W", 0.05), ("X", 0.2),
    ("Y", 0.1), ("Z", 0.05),
)  # fmt: skip
"""Per-key travel offsets fitted to the alphabet map (``tools/fit_switch_model.py``).

Positive: the key registers earlier than the shared ``actuation_travel_mm``.
The arrow keys have none: offsets fitted on half the arrows map made the
other half worse."""


@dataclass(frozen=True)
class SwitchModel:
    """Physical parameters of the tap-to-actuation model.

    Attributes:
        dome_radius_mm: effective radius of curvature of the sensor's dome
            (a 25 mm wide, 7.2 mm deep cap has 14.45 mm).
        dome_contact_radius_mm: horizontal reach of the dome from its apex
            (half its 25 mm diameter); nothing further away is touched.
        keycap_top_inset_x_mm: the region of the key top through which the
            dome pushes the key straight down is smaller than the key cell by
            this much on each side, across the rows. The fit makes it far
            smaller than the printed keycap top: a push near a keycap's edge
            rocks the cap instead.
        keycap_top_inset_y_mm: the same along the rows.
        keycap_corner_radius_mm: corner rounding of the key top, as the
            rounded-rectangle distance ``|max(|d| - (h - c), 0)| - c`` defines
            it; a radius larger than a half-size ``h`` rounds the top into a
            lens.
        actuation_travel_mm: how far the sensor must push past first contact,
            at the centre of the dome, for the key to register: the switch's
            2 mm pre-travel plus the dome's compression at the actuation force.
        compliance_mm: extra compression needed when the dome meets the key
            obliquely, scaled by ``1 / cos(theta) - 1``.
        rocking_x: extra travel per mm^p of contact offset across the rows.
        rocking_y: the same along the rows.
        rocking_exponent: ``p`` of the rocking terms.
        stabiliser_fraction: share of a wide key's extra width (beyond 1 u)
            over which its stabiliser keeps it level (no rocking).
        clearance_mm: height of the work frame origin above the key tops
            (3.5 mm on the paper's rig).
        travel_offsets_mm: ``(key name, offset)`` pairs (or a mapping): each
            named key registers ``offset`` mm earlier than
            ``actuation_travel_mm`` says (later where negative), its switch's
            own pre-travel tolerance. Keys not named have offset 0. At most
            ``SWITCH_TOLERANCE_MM`` each. Stored sorted by key, without zeros.
    """

    dome_radius_mm: float = 14.45
    dome_contact_radius_mm: float = 12.5
    keycap_top_inset_x_mm: float = 8.4954
    keycap_top_inset_y_mm: float = 7.2105
    keycap_corner_radius_mm: float = 2.8416
    actuation_travel_mm: float = 1.6041
    compliance_mm: float = -5.4013
    rocking_x: float = 0.2520
    rocking_y: float = 0.0358
    rocking_exponent: float = 0.9912
    stabiliser_fraction: float = 0.0178
    clearance_mm: float = 3.5
    travel_offsets_mm: tuple[tuple[str, float], ...] = FITTED_TRAVEL_OFFSETS_MM

    def __post_init__(self) -> None:
        for name in ("dome_radius_mm", "dome_contact_radius_mm", "actuation_travel_mm"):
            if not getattr(self, name) > 0:
                raise ValueError(f"{name} must be positive, got {getattr(self, name)!r}")
        if self.dome_contact_radius_mm > self.dome_radius_mm:
            raise ValueError("dome_contact_radius_mm cannot exceed dome_radius_mm")
        if not 0 <= self.stabiliser_fraction <= 1:
            raise ValueError(f"stabiliser_fraction must be in [0, 1], got {self.stabiliser_fraction!r}")
        for name in (
            "keycap_top_inset_x_mm",
            "keycap_top_inset_y_mm",
            "keycap_corner_radius_mm",
            "rocking_x",
            "rocking_y",
            "rocking_exponent",
        ):
            if getattr(self, name) < 0:
                raise ValueError(f"{name} must be non-negative, got {getattr(self, name)!r}")
        given = self.travel_offsets_mm
        try:
            pairs = [(str(name), float(offset)) for name, offset in (
                given.items() if isinstance(given, Mapping) else given
            )]  # fmt: skip
        except (TypeError, ValueError):
            raise ValueError(
                f"travel_offsets_mm must be a mapping or (key name, offset in mm) pairs, got {given!r}"
            ) from None
        offsets = dict(pairs)
        if len(offsets) != len(pairs):
            twice = sorted({name for name, _ in pairs if [n for n, _ in pairs].count(name) > 1})
            raise ValueError(f"travel_offsets_mm names {', '.join(twice)} more than once")
        unknown = sorted(set(offsets) - {key.name for key in KeyboardLayout().keys})
        if unknown:
            raise ValueError(f"travel_offsets_mm names keys the keyboard does not have: {unknown}")
        for name, offset in offsets.items():
            if not abs(offset) <= SWITCH_TOLERANCE_MM:
                raise ValueError(
                    f"travel offset of {name} must be within +/- {SWITCH_TOLERANCE_MM} mm "
                    f"(the switch's pre-travel tolerance), got {offset!r}"
                )
            if not offset < self.actuation_travel_mm:
                raise ValueError(
                    f"travel offset of {name} ({offset} mm) must be less than actuation_travel_mm "
                    f"({self.actuation_travel_mm} mm): the key would register before it is touched"
                )
        # One spelling per model: sorted by key, zeros dropped (equal switches compare equal).
        object.__setattr__(self, "travel_offsets_mm", tuple(sorted((k, v) for k, v in offsets.items() if v)))

    def travel_offsets(self, layout: KeyboardLayout) -> np.ndarray:
        """(n_keys,) travel offset of each key of ``layout`` (0 for keys not named); read-only."""
        return _offsets_by_index(self.travel_offsets_mm, layout)

    def keycap_top_half_size_mm(self, layout: KeyboardLayout) -> np.ndarray:
        """(n_keys, 2) half-sizes (x, y) of each key's flat top."""
        half_x = np.full(len(layout), layout.pitch_mm / 2 - self.keycap_top_inset_x_mm)
        half_y = layout.widths_u * layout.pitch_mm / 2 - self.keycap_top_inset_y_mm
        return np.stack([half_x, half_y], axis=-1)

    def _contact_geometry(
        self, layout: KeyboardLayout, x_mm: np.ndarray, y_mm: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Offsets of the contact point from each key centre, and its distance.

        Returns ``(|e_x|, |e_y|, r)``, each of shape (..., n_keys): the contact
        point (the apex clamped onto the key top) and the horizontal distance
        from the apex to the rounded key top (0 over it).
        """
        points = np.stack([np.asarray(x_mm, float), np.asarray(y_mm, float)], axis=-1)
        offset = np.abs(points[..., None, :] - layout.centres_mm)
        half_size = self.keycap_top_half_size_mm(layout)
        corner = self.keycap_corner_radius_mm
        q = offset - (half_size - corner)
        r = np.maximum(np.linalg.norm(np.maximum(q, 0.0), axis=-1) - corner, 0.0)
        contact = np.minimum(offset, half_size)
        return contact[..., 0], contact[..., 1], r

    def distance_to_key_tops_mm(
        self, layout: KeyboardLayout, x_mm: np.ndarray, y_mm: np.ndarray
    ) -> np.ndarray:
        """Horizontal distance from each point to each key top, shape (..., n_keys).

        Zero over a key top; the tops are rounded rectangles.
        """
        return self._contact_geometry(layout, x_mm, y_mm)[2]

    def actuation_margin_mm(
        self, layout: KeyboardLayout, x_mm: np.ndarray, y_mm: np.ndarray, depth_mm: np.ndarray
    ) -> np.ndarray:
        """How far past its actuation point each key is pushed, shape (..., n_keys).

        Negative where the key does not register; ``-inf`` where the dome
        cannot reach the key at all.
        """
        contact_x, contact_y, r = self._contact_geometry(layout, x_mm, y_mm)
        stabilised = self.stabiliser_fraction * np.maximum((layout.widths_u - 1.0) * layout.pitch_mm / 2, 0.0)
        rocking_y = np.maximum(contact_y - stabilised, 0.0)
        radius = self.dome_radius_mm
        reachable = r < self.dome_contact_radius_mm
        cos_theta = np.sqrt(1.0 - (np.minimum(r, self.dome_contact_radius_mm) / radius) ** 2)
        required = (
            self.actuation_travel_mm
            - self.travel_offsets(layout)
            + radius * (1.0 - cos_theta)
            + self.compliance_mm * (1.0 / cos_theta - 1.0)
            + self.rocking_x * contact_x**self.rocking_exponent
            + self.rocking_y * rocking_y**self.rocking_exponent
        )
        penetration = np.asarray(depth_mm, float)[..., None] - self.clearance_mm
        return np.where(reachable, penetration - required, -np.inf)

    def pressed_key_index(
        self, layout: KeyboardLayout, x_mm: np.ndarray, y_mm: np.ndarray, depth_mm: np.ndarray
    ) -> np.ndarray:
        """Index of the actuated key for each tap, or -1 where none actuates.

        Args:
            layout: the keyboard.
            x_mm, y_mm: tap positions of the dome's apex in the keyboard frame.
            depth_mm: tap depths below the work-frame origin (same shape).
        """
        margin = self.actuation_margin_mm(layout, x_mm, y_mm, depth_mm)
        best = np.argmax(margin, axis=-1)
        pressed = np.take_along_axis(margin, best[..., None], axis=-1)[..., 0] >= 0.0
        return np.where(pressed, best, -1)


@functools.lru_cache(maxsize=16)
def _offsets_by_index(offsets: tuple[tuple[str, float], ...], layout: KeyboardLayout) -> np.ndarray:
    """The offsets as an array over ``layout``'s keys, built once per (offsets, layout): every tap
    computes actuation margins."""
    array = np.zeros(len(layout))
    for name, offset in offsets:
        array[layout.key(name).index] = offset
    array.flags.writeable = False
    return array
