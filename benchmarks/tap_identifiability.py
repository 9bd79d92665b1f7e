"""How well one tap tells where the sensor is: the continuous tasks' start observations.

A continuous episode starts at a uniformly random pose with a 4 mm tap there
(read 2 mm deeper in the released simulator's world, ``tap_depth="released"``).
A policy that presses the goal key in the fewest steps (the typing bound of
``benchmarks/typing_bounds.py``, about 1.2-1.3 steps a key on the arrows) must
know from that one image where it is. This script resets each world many
times, through the environments' public API only, and asks of the start
images alone:

* how far apart two start poses can be whose images are the same, or differ
  in at most ``tau`` of the 10,000 pixels (columns ``>= 5 mm at tau``: the
  share of starts whose image has such a twin at least 5 mm away, which one
  tap cannot tell apart);
* how many pixels change between starts about 1 mm apart (the grid's pitch),
  and the fewest that tell apart two starts at least 5 mm apart.

On the dataset backend a tap reads the nearest stored sample, so starts
within half a millimetre of each other share an image by construction; the
twins counted here are at least 5 mm apart (the default datasets' grid is
1 mm; on a grid of 5 mm or coarser one sample's own starts would count).

Run: python benchmarks/tap_identifiability.py [--resets 4000] [--taus 0 50 100]
"""

from __future__ import annotations

import argparse
import time

import gymnasium as gym
import numpy as np

import tactile_braille  # noqa: F401 - registers the environments
from tactile_braille.envs.core import RELEASED_DEPTH_SHIFT_MM
from tactile_braille.envs.tasks import RESET_TAP_DEPTH_MM

WORLDS = (
    ("ours", {}),
    ("released simulator's", {"edges": "overrun", "tap_depth": "released"}),
)


def start_images(task: str, options: dict, resets: int, seed: int) -> list[tuple[np.ndarray, np.ndarray]]:
    """The distinct start images (0/1 rows) of ``resets`` resets, each with the poses (mm) it began at."""
    env = gym.make(f"tactile_braille/{task}", **options)
    images: dict[bytes, tuple[np.ndarray, list[np.ndarray]]] = {}
    for i in range(resets):
        observation, info = env.reset(seed=seed + i)
        image = observation["observation"][..., 0] > 0
        pose = np.asarray(info["sensor_pose_mm"][:2], dtype=float)
        images.setdefault(image.tobytes(), (image.ravel(), []))[1].append(pose)
    env.close()
    return [(image, np.array(poses)) for image, poses in images.values()]


def _distances(points: np.ndarray) -> np.ndarray:
    """Pairwise Euclidean distances (mm) between the rows of ``points``."""
    return np.sqrt(((points[:, None] - points[None]) ** 2).sum(-1))


def measure(groups: list[tuple[np.ndarray, np.ndarray]], taus: list[int]) -> dict[str, float]:
    """Shares of starts with a twin image >= 5 mm away, and the pixels that change 1 mm apart."""
    rows = np.array([image for image, _ in groups], dtype=np.float32)
    starts = np.array([len(poses) for _, poses in groups], dtype=float)
    centre = np.array([poses.mean(0) for _, poses in groups])
    # an image seen from poses >= 5 mm apart is its own twin
    # (the nearest-sample lookup alone keeps one image's poses within ~0.7 mm)
    spread = np.array([_distances(poses).max() for _, poses in groups])
    on = rows.sum(1)
    hamming = on[:, None] + on[None, :] - 2.0 * rows @ rows.T
    apart = _distances(centre)
    neighbours = (apart > 0.5) & (apart < 1.5)
    out = {
        "starts": float(starts.sum()),
        "images": float(len(rows)),
        "pixels on": float((on * starts).sum() / starts.sum()),
        "1 mm apart": float(np.median(hamming[neighbours])) if neighbours.any() else float("nan"),
        "fewest 5 mm apart": float(hamming[apart >= 5.0].min()) if (apart >= 5.0).any() else float("nan"),
    }
    for tau in taus:
        twin = ((hamming <= tau) & (apart >= 5.0)).any(1) | (spread >= 5.0)
        out[f">= 5 mm at {tau}"] = float((twin * starts).sum() / starts.sum())
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--resets", type=int, default=4000, help="resets per task and world")
    parser.add_argument("--taus", type=int, nargs="+", default=[0, 50, 100], help="pixel tolerances")
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    if args.resets < 2 or any(t < 0 for t in args.taus):
        parser.error("--resets must be at least 2 and every --taus at least 0")
    header = ["task", "world", "start tap read at (mm)", "starts", "distinct images", "pixels on"]
    header += ["median change 1 mm apart", "fewest changed >= 5 mm apart"]
    header += [f"twin >= 5 mm away, tau {t}" for t in args.taus]
    print("| " + " | ".join(header) + " |")
    print("|" + "---|" * len(header))
    for task in ("ContinuousArrows-v0", "ContinuousAlphabet-v0"):
        for world, options in WORLDS:
            started = time.perf_counter()
            m = measure(start_images(task, options, args.resets, args.seed), args.taus)
            shift = RELEASED_DEPTH_SHIFT_MM if options.get("tap_depth") == "released" else 0.0
            cells = [task, world, f"{RESET_TAP_DEPTH_MM + shift:.0f}", f"{m['starts']:.0f}"]
            cells += [f"{m['images']:.0f}", f"{m['pixels on']:.0f}", f"{m['1 mm apart']:.0f}"]
            cells += [f"{m['fewest 5 mm apart']:.0f}"] + [f"{m[f'>= 5 mm at {t}']:.1%}" for t in args.taus]
            print("| " + " | ".join(cells) + f" |  ({time.perf_counter() - started:.0f} s)")


if __name__ == "__main__":
    main()
