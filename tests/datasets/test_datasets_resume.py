"""A collection killed with SIGKILL keeps its finished shards and resumes to the same dataset."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import numpy as np
import pytest

import tactile_braille
from conftest_datasets import CountingRig, assert_same_arrays, collect, collect_to, shard_indices
from tactile_braille.datasets.procedures import PerturbedTaps
from tactile_braille.datasets.store import DatasetError, load_dataset
from tactile_braille.rigs.virtual import VirtualRig

pytestmark = pytest.mark.skipif(not hasattr(signal, "SIGKILL"), reason="needs POSIX signals")

PROCEDURE = PerturbedTaps(keys="all", per_key=13)  # 32 classes x 13 = 416 taps
SEED = 7
SHARD_SIZE = 16

# The child's rig sleeps a little per tap, so that the collection is certainly
# still running when the parent kills it (the samples do not depend on it).
CHILD = textwrap.dedent(
    """
    import sys
    import time

    from tactile_braille.datasets.collector import collect
    from tactile_braille.datasets.procedures import PerturbedTaps
    from tactile_braille.rigs.virtual import VirtualRig


    class SlowRig(VirtualRig):
        def tap(self, *args, **kwargs):
            time.sleep(0.01)
            return super().tap(*args, **kwargs)


    collect(
        SlowRig(seed=0), PerturbedTaps(keys="all", per_key=13), sys.argv[1],
        seed=int(sys.argv[2]), shard_size=int(sys.argv[3]), progress=False,
    )
    """
)


@pytest.fixture(autouse=True)
def _isolated_cache(tmp_path, monkeypatch):
    monkeypatch.setenv("TACTILE_BRAILLE_DATA", str(tmp_path / "cache"))


def _child_env() -> dict[str, str]:
    env = dict(os.environ)
    source = str(Path(tactile_braille.__file__).resolve().parents[1])
    env["PYTHONPATH"] = os.pathsep.join(p for p in (source, env.get("PYTHONPATH")) if p)
    return env


def _kill_after_shards(output: Path, min_shards: int, timeout_s: float = 60.0) -> list[int]:
    """Start the child collection, SIGKILL it once ``min_shards`` shards exist; return their taps."""
    partial = output.with_name(output.name + ".partial")
    child = subprocess.Popen(
        [sys.executable, "-c", CHILD, str(output), str(SEED), str(SHARD_SIZE)],
        env=_child_env(),
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
    )
    try:
        deadline = time.monotonic() + timeout_s
        while len(list(partial.glob("shard-*.h5"))) < min_shards:
            if child.poll() is not None:
                _, err = child.communicate()
                pytest.fail(
                    f"the collection ended (rc {child.returncode}) before it was killed: {err.decode()}"
                )
            if time.monotonic() > deadline:
                pytest.fail(f"no {min_shards} shards appeared in {partial} within {timeout_s} s")
            time.sleep(0.005)
        assert child.poll() is None, "the collection finished before it could be killed"
        os.kill(child.pid, signal.SIGKILL)
        child.communicate(timeout=30)
    finally:
        if child.poll() is None:
            child.kill()
            child.wait()
    assert child.returncode == -signal.SIGKILL
    return shard_indices(partial)


def test_sigkilled_collection_resumes_to_the_uninterrupted_dataset(tmp_path):
    output = tmp_path / "killed.h5"
    partial = tmp_path / "killed.h5.partial"
    on_disk = _kill_after_shards(output, min_shards=2)

    # Nothing half-written: no output file, whole shards of 16 consecutive taps.
    assert not output.exists()
    assert (partial / "manifest.json").exists()
    assert len(on_disk) >= 2 * SHARD_SIZE
    assert len(on_disk) < len(PROCEDURE)
    assert on_disk == list(range(len(on_disk)))  # a prefix of the procedure
    assert len(on_disk) % SHARD_SIZE == 0
    shards_before = sorted(p.name for p in partial.glob("shard-*.h5"))

    # Refusals: no resume flag, or other settings; the shards stay as they were.
    with pytest.raises(FileExistsError, match="interrupted collection"):
        collect(VirtualRig(seed=0), PROCEDURE, output, seed=SEED, shard_size=SHARD_SIZE, progress=False)
    with pytest.raises(DatasetError, match="cannot resume"):
        collect(VirtualRig(seed=0), PROCEDURE, output, seed=SEED + 1, resume=True, progress=False)
    assert sorted(p.name for p in partial.glob("shard-*.h5")) == shards_before
    assert shard_indices(partial) == on_disk

    rig = CountingRig(seed=0)
    collect(rig, PROCEDURE, output, seed=SEED, resume=True, shard_size=SHARD_SIZE, progress=False)
    assert rig.calls == len(PROCEDURE) - len(on_disk)
    assert not partial.exists()

    resumed = load_dataset(output)
    assert len(resumed) == len(PROCEDURE) == 416
    np.testing.assert_array_equal(resumed.tap_index, np.arange(len(PROCEDURE)))
    assert len(np.unique(resumed.tap_index)) == len(resumed)

    reference = collect_to(tmp_path / "reference.h5", PROCEDURE, seed=SEED, shard_size=SHARD_SIZE)
    assert_same_arrays(resumed, reference)
    assert resumed.metadata == reference.metadata

    # A finished file is never overwritten, resume or not.
    with pytest.raises(FileExistsError, match="exists already"):
        collect(VirtualRig(seed=0), PROCEDURE, output, seed=SEED, resume=True, progress=False)
