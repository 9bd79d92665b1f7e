"""Tactile datasets: collection procedures for any rig, a crash-safe HDF5 store,
the original release's importer and the default datasets cache."""

from tactile_braille.datasets.cache import DEFAULT_DATASETS, data_dir, default_dataset, default_dataset_path
from tactile_braille.datasets.collector import GENERATOR_VERSION, collect, dataset_metadata
from tactile_braille.datasets.procedures import GridTaps, PerturbedTaps, TapSpec
from tactile_braille.datasets.store import (
    FORMAT_VERSION,
    DatasetError,
    DatasetMetadata,
    DatasetWriter,
    TactileDataset,
    load_dataset,
)

__all__ = [
    "DEFAULT_DATASETS",
    "FORMAT_VERSION",
    "GENERATOR_VERSION",
    "DatasetError",
    "DatasetMetadata",
    "DatasetWriter",
    "GridTaps",
    "PerturbedTaps",
    "TactileDataset",
    "TapSpec",
    "collect",
    "data_dir",
    "dataset_metadata",
    "default_dataset",
    "default_dataset_path",
    "load_dataset",
]
