"""Helpers shared by the environment tests (imported by name: pytest puts tests/ on sys.path)."""

from __future__ import annotations

import numpy as np


def assert_same(left, right, where: str = "") -> None:
    """Recursive exact equality of outputs: dicts, tuples, lists, arrays (with dtypes) and scalars."""
    if isinstance(left, dict):
        assert isinstance(right, dict), where
        assert left.keys() == right.keys(), where
        for key in left:
            assert_same(left[key], right[key], f"{where}[{key!r}]")
    elif isinstance(left, (tuple, list)):
        assert len(left) == len(right), where
        for i, (a, b) in enumerate(zip(left, right, strict=True)):
            assert_same(a, b, f"{where}[{i}]")
    elif isinstance(left, np.ndarray):
        assert isinstance(right, np.ndarray), where
        assert left.dtype == right.dtype, where
        np.testing.assert_array_equal(left, right, err_msg=where)
    else:
        assert left == right, f"{where}: {left!r} != {right!r}"
