"""The simulated TacTip and the image processing shared by real and rendered frames."""

from tactile_braille.sensor.config import (
    PRESETS,
    ImageProcessing,
    Nuisance,
    TacTipConfig,
    sensor_preset,
)
from tactile_braille.sensor.processing import process_frame
from tactile_braille.sensor.tactip import TacTip

__all__ = [
    "PRESETS",
    "ImageProcessing",
    "Nuisance",
    "TacTip",
    "TacTipConfig",
    "process_frame",
    "sensor_preset",
]
