"""The worlds the transfer tests type in."""

from __future__ import annotations

import numpy as np
import pytest

from tactile_braille.evaluation.worlds import TRANSFER_SUITE, World, expand_worlds, parse_world


def test_worlds_are_parsed_from_their_names():
    assert parse_world("render") == World("render")
    assert parse_world("sensor:tactip_127") == World("sensor:tactip_127", sensor="tactip_127")
    assert parse_world("frame:1,-0.5,2") == World("frame:+1,-0.5,+2", offset_mm=(1.0, -0.5), rotation_deg=2.0)
    assert parse_world("frame:+0,1.0,-2").name == "frame:0,+1,-2"  # one name per world
    for bad, message in (
        ("frame:1,2", "frame:DX,DY,DEG"),
        ("frame:a,b,c", "frame:DX,DY,DEG"),
        ("sensor:gelsight", "unknown sensor 'gelsight'"),
        ("dataset", "unknown world 'dataset'"),
    ):
        with pytest.raises(ValueError, match=message):
            parse_world(bad)


def test_the_transfer_suite_expands_once_in_order():
    worlds = expand_worlds(["render", "transfer", "frame:1,0,2"])
    assert [w.name for w in worlds] == list(TRANSFER_SUITE)
    assert sum(w.offset_mm != (0.0, 0.0) for w in worlds) == 4 and {abs(w.rotation_deg) for w in worlds} == {
        0,
        2,
    }


@pytest.mark.parametrize("name", ["render", "frame:+1,0,+2", "sensor:tactip_127"])
def test_each_world_makes_a_live_environment_of_the_task(name):
    env = parse_world(name).make_env("tactile_braille/ContinuousArrows-v0", "braille_331", proprio=True)
    observation, _ = env.reset(seed=0)
    assert observation["observation"].shape == (100, 100, 1) and "sensor_pose" in observation
    observation, *_ = env.step(np.array([0.1, -0.1, -1.0], dtype=np.float32))
    world = env.unwrapped.world
    assert world["sensor"]["name"] == ("tactip_127" if "sensor" in name else "braille_331")
    assert ("work_frame_error" in world) == name.startswith("frame")
    env.close()
