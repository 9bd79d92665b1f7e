"""A touch encoder learnt from labelled taps: supervised learning on what the robot knows.

A robot knows three things about every tap without touch: where the sensor
was (the arm's kinematics), which key lies under it there (the calibrated
keyboard layout, :class:`KeyLocator`) and which key, if any, the keyboard
reported. :class:`LabelledTaps` holds tactile images with those labels
(:func:`observation_label` reads them off an environment's step), and
:func:`fit_touch_encoder` fits a :class:`TouchEncoder` (the paper's
convolutions, :class:`~tactile_braille.supervised.networks.Encoder`, a
projection to a few features, three heads) to predict the three from the
image, with the supervised fit loop the key classifier uses
(:func:`~tactile_braille.supervised.fit.fit_minibatches`).

It is supervised learning on labelled images, like the key classifier, so it
lives here; the reinforcement-learning side lives in
:mod:`~tactile_braille.agents.touch` (``TouchAgent``: an agent acting on the
frozen encoder's features) and :mod:`~tactile_braille.agents.training` (the taps
are the run's own steps, labelled in its replay, and the encoder is refitted
on them every ``touch.refit_every`` steps). Nothing about the goal or the
reward is used.

The ``tactile`` track has no such labels: :func:`fit_touch_odometry` fits the
same encoder (``labels="observation"``) on what the observations of the run's
steps carry (:class:`Transitions`: consecutive frames, the documented effect
of each previous action, the achieved goals): touch odometry, the pressed key,
the key a step presses, and where each key lies from the sensor, learnt in
hindsight from the run's presses (:func:`hindsight_offsets`).

>>> import numpy as np
>>> taps = LabelledTaps()
>>> taps.add(np.zeros((100, 100, 1), np.uint8), np.array([0.0, 1.0, 4.0]), pressed=-1)
>>> len(taps)
1
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import torch
from torch import nn
from torch.nn import functional as F

from tactile_braille.supervised.fit import adam, fit_minibatches
from tactile_braille.supervised.networks import IMAGE_SIZE_PX, Encoder

TOUCH_LABELS = ("robot", "observation")
"""What a touch encoder learns from: ``"robot"``, what a calibrated robot knows of every tap (the arm's
pose, the key the layout places under the sensor, the key pressed); ``"observation"``, the observation
dictionary alone (the previous action and the pressed key; :func:`fit_touch_odometry`)."""


@dataclass(frozen=True)
class TouchEncoderConfig:
    """How the touch encoder is made and fitted.

    Attributes:
        features: length of the feature vector the agent sees.
        hidden: units of the projection between the convolutions and the features.
        epochs: passes over the labelled taps.
        batch_size: taps per gradient step.
        learning_rate: Adam's step size.
        validation: fraction of the taps held out to report the fit.
    """

    features: int = 64
    hidden: int = 256
    epochs: int = 40
    batch_size: int = 64
    learning_rate: float = 1e-3
    validation: float = 0.1

    def __post_init__(self) -> None:
        for name in ("features", "hidden", "epochs", "batch_size"):
            if getattr(self, name) < 1:
                raise ValueError(f"TouchEncoderConfig.{name} must be at least 1, got {getattr(self, name)}")
        if self.learning_rate <= 0:
            raise ValueError(f"TouchEncoderConfig.learning_rate must be positive, got {self.learning_rate}")
        if not 0.0 <= self.validation < 1.0:
            raise ValueError(f"TouchEncoderConfig.validation must be in [0, 1), got {self.validation}")


class TouchEncoder(nn.Module):
    """The paper's convolutions, a projection to ``features`` (layer-normalised), and three heads.

    The heads predict the sensor pose (x, y, depth in mm, through the
    labels' mean and spread kept as buffers), the pressed key and the key
    under the sensor (each over the ``keys`` task keys and a last class for
    none or another key).
    """

    def __init__(self, keys: int, features: int = 64, hidden: int = 256, labels: str = "robot") -> None:
        super().__init__()
        if labels not in TOUCH_LABELS:
            raise ValueError(f"labels must be one of {TOUCH_LABELS}, got {labels!r}")
        self.encoder = Encoder()
        self.project = nn.Sequential(
            nn.Linear(Encoder.output_size, hidden),
            nn.ReLU(),
            nn.Linear(hidden, features),
            nn.LayerNorm(features),
        )
        self.pose = nn.Linear(features, 3)
        self.key = nn.Linear(features, keys + 1)
        self.labels = labels
        if labels == "robot":
            self.under = nn.Linear(features, keys + 1)
        else:
            # What a step from here presses, given its action's effects (move, depth code): the key
            # under the sensor is what a press without a move presses.
            self.outcome = nn.Sequential(
                nn.Linear(features + 3, hidden), nn.ReLU(), nn.Linear(hidden, keys + 1)
            )
            # Where each key lies from here, in action units: the moves that led to pressing it.
            self.offsets = nn.Linear(features, 2 * keys)
        self.register_buffer("pose_mean", torch.zeros(3))
        self.register_buffer("pose_scale", torch.ones(3))
        self.keys, self.features_size = keys, features

    def features(self, images: torch.Tensor) -> torch.Tensor:
        """(B, features) from (B, 1, 100, 100) images."""
        return self.project(self.encoder(images))

    def forward(self, images: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """Normalised pose predictions (B, 3) and pressed-key logits (B, keys + 1)."""
        features = self.features(images)
        return self.pose(features), self.key(features)

    def heads(self, images: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """Pose predictions, pressed-key logits and under-the-sensor logits."""
        features = self.features(images)
        if self.labels == "robot":
            return self.pose(features), self.key(features), self.under(features)
        here = features.new_tensor(PRESS_HERE).expand(len(features), 3)
        return self.pose(features), self.key(features), self.press_outcome(features, here)

    def press_outcome(self, features: torch.Tensor, effects: torch.Tensor) -> torch.Tensor:
        """Logits (B, keys + 1) of the key a step with these effects (B, 3) presses from frames of
        these features (the last class: none); encoders fitted on observations only."""
        return self.outcome(torch.cat([features, effects], -1))

    def standardise(self, poses_mm: np.ndarray) -> np.ndarray:
        """Poses in mm, (..., 3) or (..., 2) for x and y, in the pose head's standardised coordinates
        (the labels' mean and spread at the last fit)."""
        size = np.shape(poses_mm)[-1]
        mean, scale = self.pose_mean.cpu().numpy()[:size], self.pose_scale.cpu().numpy()[:size]
        return ((poses_mm - mean) / scale).astype(np.float32)

    @property
    def readout_size(self) -> int:
        """Length of :meth:`read`'s vectors: the pose and two key distributions (and, for an encoder
        fitted on observations, each key's offset from the sensor)."""
        return 3 + 2 * (self.keys + 1) + 2 * self.keys * (self.labels == "observation")

    @torch.no_grad()
    def encode(self, images: np.ndarray) -> np.ndarray:
        """Features of uint8 images ((B, 1, 100, 100) or (B, 100, 100, 1)) as float32 (B, features)."""
        return self.features(self._tensor(images)).float().cpu().numpy()

    @torch.no_grad()
    def read(self, images: np.ndarray) -> np.ndarray:
        """What the heads read from images, float32 (B, :attr:`readout_size`): the standardised pose,
        then the probabilities of the pressed key and of the key under the sensor.

        Unlike the features, whose meaning a refit is free to change, each number keeps its meaning
        from one fit to the next: a learner on the readout keeps what it learnt when the encoder improves.
        The pose's standardisation is the labels' mean and spread at the last fit, which settles as
        taps accumulate (in a continuous-alphabet run, it moves by about 1-1.5 % of the spread from one
        refit to the next after the first 5,000 taps).
        """
        tensor = self._tensor(images)
        pose, pressed, under = self.heads(tensor)
        parts = [pose, pressed.softmax(-1), under.softmax(-1)]
        if self.labels == "observation":  # each key's offset from the sensor, (x, y) per key
            parts.append(self.offsets(self.features(tensor)))
        return torch.cat(parts, -1).float().cpu().numpy()

    def _tensor(self, images: np.ndarray) -> torch.Tensor:
        images = np.asarray(images)
        if images.ndim == 4 and images.shape[-1] == 1:
            images = np.moveaxis(images, -1, 1)
        return torch.as_tensor(images, device=self.pose_mean.device)


class KeyLocator:
    """The task key whose cell (keycap plus its share of the gap) holds a keyboard-frame position.

    Args:
        layout: the keyboard (calibrated: its frame is the rig's).
        keys: the task's keys, in goal order.
    """

    def __init__(self, layout, keys) -> None:
        self.centres = np.array([layout.centre_mm(k) for k in keys])
        # Cells on the layout's own pitch (``Key.footprint_mm`` assumes the nominal 19 mm).
        pitch = layout.pitch_mm
        self.half = np.array([(pitch, layout.key(k).width_u * pitch) for k in keys]) / 2

    def __call__(self, pose_mm: np.ndarray) -> int:
        """Goal index of the key under (x, y), -1 for none of the task's keys."""
        inside = np.flatnonzero((np.abs(self.centres - np.asarray(pose_mm)[:2]) < self.half).all(-1))
        return int(inside[0]) if len(inside) else -1


class LabelledTaps:
    """Tactile images with the arm's pose, the key under the sensor and the key the keyboard reports.

    Keys are goal indices, -1 for none (or a key outside the task).
    """

    def __init__(self) -> None:
        self.images: list[np.ndarray] = []
        self.poses: list[np.ndarray] = []
        self.pressed: list[int] = []
        self.under: list[int] = []

    def __len__(self) -> int:
        return len(self.images)

    def add(self, image: np.ndarray, pose_mm: np.ndarray, pressed: int, under: int = -1) -> None:
        """One tap: a 100x100 image, the sensor's (x, y, depth) in mm, the pressed key, the key under it."""
        self.images.append(np.asarray(image, dtype=np.uint8).reshape(IMAGE_SIZE_PX, IMAGE_SIZE_PX))
        self.poses.append(np.asarray(pose_mm, dtype=np.float32)[:3])
        self.pressed.append(int(pressed))
        self.under.append(int(under))

    def add_observation(
        self, observation: dict[str, np.ndarray], info: dict, locate: KeyLocator | None = None
    ) -> None:
        """A tap as an environment reports it (``sensor_pose_mm`` in info, the achieved goal)."""
        x, y, depth, pressed, under = observation_label(observation, info, locate)
        self.add(observation["observation"], np.array([x, y, depth]), int(pressed), int(under))

    def arrays(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Images (N, 1, 100, 100) uint8, poses (N, 3) float32, pressed keys (N,) int64."""
        return np.stack(self.images)[:, None], np.stack(self.poses), np.array(self.pressed, dtype=np.int64)

    @classmethod
    def from_arrays(cls, images, poses, pressed, under) -> LabelledTaps:
        """Taps from arrays (as :meth:`EpisodeReplayBuffer.labelled_frames` returns them)."""
        if not (len(images) == len(poses) == len(pressed) == len(under)):
            raise ValueError("images, poses and keys differ in number")
        taps = cls()
        for image, pose, key, below in zip(images, poses, pressed, under, strict=True):
            taps.add(image, pose, int(key), int(below))
        return taps

    @staticmethod
    def label(pose_mm: np.ndarray, pressed: int, under: int) -> np.ndarray:
        """A frame's labels as the replay stores them: x, y, depth, pressed key, key under the sensor."""
        return np.array([*np.asarray(pose_mm, dtype=np.float32)[:3], pressed, under], dtype=np.float32)


def observation_label(
    observation: dict[str, np.ndarray], info: dict, locate: KeyLocator | None
) -> np.ndarray:
    """The labels of an environment's observation (:meth:`LabelledTaps.label`): the sensor pose in
    ``info``, the pressed task key from the achieved goal, and the key under the sensor (-1 without
    a locator)."""
    achieved = observation["achieved_goal"]
    pose = info["sensor_pose_mm"]
    pressed = int(achieved.argmax()) if achieved.any() else -1
    return LabelledTaps.label(pose, pressed, locate(pose) if locate is not None else -1)


def fit_touch_encoder(
    taps: LabelledTaps,
    keys: int,
    config: TouchEncoderConfig | None = None,
    seed: int = 0,
    device: str | torch.device = "cpu",
    init: TouchEncoder | None = None,
) -> tuple[TouchEncoder, dict[str, float]]:
    """Fit a :class:`TouchEncoder` to labelled taps; returns it (frozen, eval mode) and held-out figures.

    ``init``: an encoder whose weights the fit starts from (a refit), else a fresh one.

    The figures, on the held-out taps: ``touch/pose_error_mm`` (median
    distance in the plane), ``touch/depth_error_mm`` (median),
    ``touch/key_accuracy`` (pressed key, "none" included),
    ``touch/under_accuracy`` (key under the sensor, "none" included), plus
    the number of taps (``touch/taps``).
    """
    config = config or TouchEncoderConfig()
    if len(taps) < 10:
        raise ValueError(f"the touch encoder needs at least 10 labelled taps, got {len(taps)}")
    images, poses, pressed = taps.arrays()
    under = np.array(taps.under, dtype=np.int64)
    if max(pressed.max(), under.max()) >= keys:
        raise ValueError(
            f"a tap is labelled with key {max(pressed.max(), under.max())}, but the task has {keys} keys"
        )
    generator = torch.Generator().manual_seed(seed)
    rng = np.random.default_rng(seed)
    order = rng.permutation(len(taps))
    held = order[: min(round(config.validation * len(taps)), len(taps) - 1)]  # keep one tap to train on
    train = order[len(held) :]
    device = torch.device(device)
    model = TouchEncoder(keys, config.features, config.hidden).to(device)
    if init is not None:
        model.load_state_dict(init.state_dict())
        model.requires_grad_(True)
    mean, scale = poses[train].mean(0), poses[train].std(0) + 1e-3
    model.pose_mean.copy_(torch.as_tensor(mean))
    model.pose_scale.copy_(torch.as_tensor(scale))
    images_t = torch.as_tensor(images, device=device)
    targets = torch.as_tensor((poses - mean) / scale, device=device)
    labels = torch.as_tensor(np.where(pressed < 0, keys, pressed), device=device)
    under_labels = torch.as_tensor(np.where(under < 0, keys, under), device=device)
    optimiser = adam(model.parameters(), config.learning_rate)
    steps = config.epochs * math.ceil(len(train) / config.batch_size)
    schedule = torch.optim.lr_scheduler.OneCycleLR(optimiser, config.learning_rate, total_steps=steps)
    train_index = torch.as_tensor(train, device=device)

    def batch_loss(batch: torch.Tensor) -> torch.Tensor:
        index = train_index[batch.to(device)]
        pose, logits, under_logits = model.heads(images_t[index])
        return (
            F.smooth_l1_loss(pose, targets[index])
            + F.cross_entropy(logits, labels[index])
            + F.cross_entropy(under_logits, under_labels[index])
        )

    fit_minibatches(
        model, len(train), batch_loss, optimiser, config.epochs, config.batch_size, generator, schedule
    )
    model.eval().requires_grad_(False)
    metrics = {"touch/taps": float(len(taps))}
    if len(held):
        with torch.no_grad():
            pose, logits, under_logits = model.heads(images_t[torch.as_tensor(held, device=device)])
        error = (pose.cpu().numpy() - targets[held].cpu().numpy()) * scale
        metrics["touch/pose_error_mm"] = float(np.median(np.linalg.norm(error[:, :2], axis=-1)))
        metrics["touch/depth_error_mm"] = float(np.median(np.abs(error[:, 2])))
        metrics["touch/key_accuracy"] = float((logits.argmax(-1).cpu() == labels[held].cpu()).float().mean())
        metrics["touch/under_accuracy"] = float(
            (under_logits.argmax(-1).cpu() == under_labels[held].cpu()).float().mean()
        )
    return model, metrics


@dataclass(frozen=True)
class Transitions:
    """Consecutive frames of a run's episodes, with what the observations say of each step.

    Attributes:
        images: (N, 1, H, W) uint8 frames.
        pairs: (M, 2) indices into ``images``: a frame and the next one of its episode.
        effects: (M, 3) float32: what the step's action did as the action space documents it (the
            next frame's ``previous_action``; :func:`~tactile_braille.envs.core.action_effects`):
            the planar move in action units, then the tap's depth code.
        pressed: (M,) the key the next frame's achieved goal names (goal index, -1 none).
    """

    images: np.ndarray
    pairs: np.ndarray
    effects: np.ndarray
    pressed: np.ndarray

    def __post_init__(self) -> None:
        if not (len(self.pairs) == len(self.effects) == len(self.pressed)):
            raise ValueError("pairs, effects and pressed keys differ in number")
        if self.pairs.ndim != 2 or self.pairs.shape[1] != 2 or self.effects.shape[1:] != (3,):
            raise ValueError(f"pairs must be (M, 2) and effects (M, 3), got {self.pairs.shape}, "
                             f"{self.effects.shape}")  # fmt: skip
        if len(self.pairs) and (self.pairs.min() < 0 or self.pairs.max() >= len(self.images)):
            raise ValueError(
                f"pairs index {len(self.images)} frames, got {self.pairs.min()}..{self.pairs.max()}"
            )


PRESS_HERE = (0.0, 0.0, 1.0)
"""The effects of a press where the sensor is (no move, full depth): the key an encoder fitted on
observations reads under the sensor is the one its press outcome gives for it."""

NOTHING_PRESSED_WEIGHT = 0.1
"""The weight, in the press-outcome loss, of a step that pressed nothing (a press weighs 1)."""

ODOMETRY_BETA = 0.05
"""Where touch odometry's loss turns from squared to absolute error, in action units: nearly an absolute
error, whose fit is the median move from one touch to the next, which the steps that a workspace edge
stopped (a minority) do not pull."""


def fit_touch_odometry(
    steps: Transitions,
    keys: int,
    config: TouchEncoderConfig | None = None,
    seed: int = 0,
    device: str | torch.device = "cpu",
    init: TouchEncoder | None = None,
) -> tuple[TouchEncoder, dict[str, float]]:
    """Fit a touch encoder on what the observations carry: its previous actions and achieved goals.

    No pose and no layout. Four objectives share the encoder's features:

    * touch odometry: the pose head learns coordinates in which every step's
      move is its action's, ``pose(next)[:2] - pose(this)[:2] = move`` (a
      structured inverse dynamics; the previous action is in the
      observation), and the tap's depth code. The coordinates are fixed up to
      a translation, set by centring them on the frames; the head is rescaled
      so that :meth:`TouchEncoder.read` gives them standardised, and
      ``pose_mean`` and ``pose_scale`` hold the action units. A workspace's
      edge stops moves (the action space's documentation says where a move
      goes, not where the edge is): the loss is nearly an absolute error
      (:data:`ODOMETRY_BETA`), so these steps do not drag the fit;
    * the pressed key, from the frame a press gave;
    * the press outcome: the key a step presses, from the frame before it and
      the step's effects (:meth:`TouchEncoder.press_outcome`; steps that press
      nothing weigh :data:`NOTHING_PRESSED_WEIGHT`). Its answer for a press
      without a move (:data:`PRESS_HERE`) is the key under the sensor.

    * hindsight offsets: from each frame of an episode that ended pressing a
      key, where that key lay, the sum of the moves to the press
      (:func:`hindsight_offsets`). The offsets head learns, for every key,
      where it lies from what the sensor feels: the layout, as touch and the
      actions tell it, relative to the sensor.

    Returns the encoder (frozen, eval mode) and figures on held-out steps
    (whose frames neighbouring training steps share: near training errors):
    ``touch/odometry_error`` (median planar error of a step, action units),
    ``touch/key_accuracy`` (pressed key, "none" included),
    ``touch/outcome_accuracy`` (the key each held-out press pressed, foreseen
    from the frame before it), ``touch/offset_error`` (median distance of a
    held-out frame's offset to its episode's pressed key, action units),
    ``touch/aimed_steps`` and ``touch/taps``.
    """
    config = config or TouchEncoderConfig()
    if len(steps.pairs) < 10:
        raise ValueError(f"touch odometry needs at least 10 steps, got {len(steps.pairs)}")
    if steps.pressed.max() >= keys:
        raise ValueError(f"a step pressed key {steps.pressed.max()}, but the task has {keys} keys")
    generator = torch.Generator().manual_seed(seed)
    known = np.flatnonzero(~np.isnan(steps.effects).any(-1))  # a reset's frame follows no action
    order = known[np.random.default_rng(seed).permutation(len(known))]
    held = order[: min(round(config.validation * len(order)), len(order) - 1)]
    train = order[len(held) :]
    device = torch.device(device)
    model = TouchEncoder(keys, config.features, config.hidden, labels="observation").to(device)
    if init is not None:
        model.load_state_dict(init.state_dict())
        model.requires_grad_(True)
    data = _StepTensors.of(steps, keys, device)
    optimiser = adam(model.parameters(), config.learning_rate)
    total = config.epochs * math.ceil(len(train) / config.batch_size)
    schedule = torch.optim.lr_scheduler.OneCycleLR(optimiser, config.learning_rate, total_steps=total)
    train_index = torch.as_tensor(train, device=device)

    def batch_loss(batch: torch.Tensor) -> torch.Tensor:
        return _odometry_loss(model, data, train_index[batch.to(device)])

    fit_minibatches(
        model, len(train), batch_loss, optimiser, config.epochs, config.batch_size, generator, schedule
    )
    model.eval().requires_grad_(False)
    with torch.no_grad():
        frames = torch.unique(data.pairs)
        poses = torch.cat([_units(model, model(data.images[chunk])[0]) for chunk in frames.split(1024)])
        _standardise_head(model, poses.mean(0), poses.std(0) + 1e-3)
    metrics = {"touch/taps": float(len(steps.images)), "touch/aimed_steps": float((data.aimed >= 0).sum())}
    if len(held):
        with torch.no_grad():
            metrics.update(_held_out_figures(model, data, torch.as_tensor(held, device=device)))
    return model, metrics


@dataclass(frozen=True)
class _StepTensors:
    """A :class:`Transitions` on the fit's device, with the labels its losses read."""

    images: torch.Tensor  # (N, 1, H, W) uint8
    pairs: torch.Tensor  # (M, 2)
    effects: torch.Tensor  # (M, 3)
    labels: torch.Tensor  # (M,) the pressed key; keys for none
    aimed: torch.Tensor  # (M,) the key the episode went on to press, -1 none
    offset: torch.Tensor  # (M, 2) where it lay from the step's first frame
    keys: int

    @classmethod
    def of(cls, steps: Transitions, keys: int, device: torch.device) -> _StepTensors:
        aimed, offset = hindsight_offsets(steps)
        return cls(
            torch.as_tensor(steps.images, device=device),
            torch.as_tensor(steps.pairs, device=device),
            torch.as_tensor(steps.effects, dtype=torch.float32, device=device),
            torch.as_tensor(np.where(steps.pressed < 0, keys, steps.pressed), device=device),
            torch.as_tensor(aimed, device=device),
            torch.as_tensor(offset, device=device),
            keys,
        )


def _units(model: TouchEncoder, pose: torch.Tensor) -> torch.Tensor:
    """The pose head's output in action units."""
    return pose * model.pose_scale + model.pose_mean


def _odometry_loss(model: TouchEncoder, data: _StepTensors, index: torch.Tensor) -> torch.Tensor:
    """The four objectives of :func:`fit_touch_odometry` on the steps ``index``."""
    features = model.features(data.images[data.pairs[index].reshape(-1)]).reshape(len(index), 2, -1)
    pose = _units(model, model.pose(features))
    effect, labels = data.effects[index], data.labels[index]
    moved = pose[:, 1, :2] - pose[:, 0, :2]
    move = F.smooth_l1_loss(moved, effect[:, :2], beta=ODOMETRY_BETA)
    depth = F.smooth_l1_loss(pose[:, 1, 2], effect[:, 2], beta=ODOMETRY_BETA)
    pressed = F.cross_entropy(model.key(features[:, 1]), labels)
    # Most steps press nothing, which their depth alone tells: they weigh less.
    weight = torch.where(labels == data.keys, NOTHING_PRESSED_WEIGHT, 1.0)
    outcome = F.cross_entropy(model.press_outcome(features[:, 0], effect), labels, reduction="none")
    outcome = (weight * outcome).sum() / weight.sum()
    # Where the key this episode went on to press lies from this frame (hindsight offsets).
    known = data.aimed[index] >= 0
    predicted = model.offsets(features[known, 0]).reshape(-1, data.keys, 2)
    predicted = predicted[torch.arange(len(predicted)), data.aimed[index][known]]
    offsets = F.smooth_l1_loss(predicted, data.offset[index][known], beta=ODOMETRY_BETA, reduction="sum")
    return move + depth + pressed + outcome + offsets / len(index)


def _held_out_figures(model: TouchEncoder, data: _StepTensors, held: torch.Tensor) -> dict[str, float]:
    """:func:`fit_touch_odometry`'s figures on the held-out steps (a fitted, frozen encoder)."""
    both = data.pairs[held]
    features = model.features(data.images[both.reshape(-1)]).reshape(len(held), 2, -1)
    pose = _units(model, model.pose(features))
    error = pose[:, 1, :2] - pose[:, 0, :2] - data.effects[held, :2]
    labels = data.labels[held]
    figures = {
        "touch/odometry_error": float(torch.linalg.norm(error, dim=-1).median()),
        "touch/key_accuracy": float((model.key(features[:, 1]).argmax(-1) == labels).float().mean()),
    }
    pressing = labels < data.keys
    if pressing.any():  # how often the key a press pressed was foreseen from the frame before it
        outcome = model.press_outcome(features[:, 0], data.effects[held]).argmax(-1)
        figures["touch/outcome_accuracy"] = float((outcome == labels)[pressing].float().mean())
    known = data.aimed[held] >= 0
    if known.any():  # how far off the offset to the key an episode went on to press was
        predicted = model.offsets(features[known, 0]).reshape(-1, data.keys, 2)
        predicted = predicted[torch.arange(len(predicted)), data.aimed[held][known]]
        figures["touch/offset_error"] = float(
            torch.linalg.norm(predicted - data.offset[held][known], dim=-1).median()
        )
    return figures


def hindsight_offsets(steps: Transitions) -> tuple[np.ndarray, np.ndarray]:
    """For each step's first frame, the key its episode went on to press (M,; -1 none) and where that
    key lay from the frame (M, 2): the sum of the moves from there to the press, in action units.

    Episodes are read off the steps' frames (a step continues the one whose next frame is its first);
    an edge that stopped a move makes its sum too long, which the fit's near-absolute loss tolerates.
    """
    count = len(steps.pairs)
    aimed = np.full(count, -1, dtype=np.int64)
    offsets = np.zeros((count, 2), dtype=np.float32)
    moves = np.nan_to_num(steps.effects[:, :2])
    continues = np.zeros(count, dtype=bool)  # step m continues step m - 1
    continues[1:] = steps.pairs[1:, 0] == steps.pairs[:-1, 1]
    key, total = -1, np.zeros(2, dtype=np.float32)
    for m in range(count - 1, -1, -1):
        if steps.pressed[m] >= 0:  # an episode's last step: it pressed a key
            key, total = int(steps.pressed[m]), np.zeros(2, dtype=np.float32)
        if key >= 0:
            total = total + moves[m]
            aimed[m], offsets[m] = key, total
        if not continues[m]:  # the episode starts here: the step before belongs to another
            key = -1
    return aimed, offsets


def _standardise_head(model: TouchEncoder, mean: torch.Tensor, scale: torch.Tensor) -> None:
    """Rescale the pose head so that it reads ``(units - mean) / scale`` (units unchanged), and keep
    ``mean`` and ``scale`` as the encoder's ``pose_mean`` and ``pose_scale``."""
    ratio = model.pose_scale / scale
    model.pose.weight.mul_(ratio[:, None])
    model.pose.bias.copy_(model.pose.bias * ratio + (model.pose_mean - mean) / scale)
    model.pose_mean.copy_(mean)
    model.pose_scale.copy_(scale)
