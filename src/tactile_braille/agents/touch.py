"""Reinforcement learning on a touch encoder's features: the agent wrapper of a touch-encoder run.

A touch-encoder run stores, with every frame of its replay, what the robot
knows about the tap without touch (the sensor's pose, the key under it, the
key the keyboard reported). After its first ``start_steps`` (random actions,
as in the paper) it fits a touch encoder to predict them from the image, and
the reinforcement learner works on the frozen encoder's features: the
updates are dense layers only, on a feature cache of the replay's images.
Every ``touch.refit_every`` steps the encoder is refitted, from its current
weights, on all labelled frames so far, and the cache is recomputed:
perception keeps improving with the run's own data. No data is added: the
labelled taps are the run's own steps, counted in its epochs.

What lives where: the encoder, its labelled taps and its fit
(``TouchEncoder``, ``TouchEncoderConfig``, ``fit_touch_encoder``,
``LabelledTaps``, ``KeyLocator``, ``observation_label``) are supervised
learning on labelled images, in :mod:`~tactile_braille.supervised.touch`;
this module holds what the agents add on top: :class:`TouchAgent`, which acts
and learns on the encoder's features (or readout), the choice of inputs
(:data:`TOUCH_INPUTS`, :func:`touch_input_size`) and the observation space
the wrapped agent is built for (:func:`feature_space`). The training loop
(:mod:`~tactile_braille.agents.training`) labels the frames and refits.
"""

from __future__ import annotations

import gymnasium as gym
import numpy as np

from tactile_braille.agents.config import TOUCH_INPUTS
from tactile_braille.envs.core import PROPRIO_KEY
from tactile_braille.supervised.touch import TouchEncoder


class TouchAgent:
    """An agent that acts on a touch encoder's features of the tactile image.

    Its ``policy_action`` takes the environment's observation (with the
    image), so evaluation, typing and trajectory figures work unchanged;
    its ``update`` takes replay batches of features. The encoder is part of
    its state and of its policy snapshots.

    With ``key_positions_mm`` (the goal keys' centres on the calibrated
    layout, keyboard frame) the goal one-hot is followed by the goal key's
    x and y, standardised as the encoder's pose targets: the goal then lives
    in the coordinates of the pose the features encode, so "where to go" is
    the same function for every key, not 27 functions to learn apart.

    Args:
        agent: an agent built for feature observations (:func:`feature_space`, of
            :func:`touch_input_size` features).
        encoder: the touch encoder (fitted later by the training loop, or loaded).
        key_positions_mm: (keys, 2) goal key centres, or None for the one-hot alone.
        inputs: what the agent learns on: the encoder's ``"features"`` or its ``"readout"``
            (:meth:`TouchEncoder.read`).
        pose_inputs: the agent also sees the arm's pose (the ``proprio`` observation's
            ``sensor_pose``; in the replay, each frame's labelled pose), standardised as the
            encoder's pose targets.
        goal_offsets: the learner sees, instead of every key's offset from the sensor that the
            readout of an encoder fitted on observations ends with
            (:func:`~tactile_braille.supervised.touch.fit_touch_odometry`), the goal key's: where
            the goal lies from what the sensor feels, learnt in hindsight from the run's presses.
    """

    def __init__(
        self,
        agent,
        encoder: TouchEncoder,
        key_positions_mm: np.ndarray | None = None,
        inputs: str = "features",
        pose_inputs: bool = False,
        goal_offsets: bool = False,
    ) -> None:
        if inputs not in TOUCH_INPUTS:
            raise ValueError(f"inputs must be one of {TOUCH_INPUTS}, got {inputs!r}")
        if goal_offsets and (key_positions_mm is not None or encoder.labels != "observation"):
            raise ValueError(
                "goal_offsets takes the key offsets of an encoder fitted on observations "
                "(labels='observation'), and no calibrated key_positions_mm"
            )
        if goal_offsets and pose_inputs:
            raise ValueError("goal_offsets reads the readout's last numbers, which pose_inputs would take")
        if goal_offsets and inputs != "readout":
            raise ValueError("goal_offsets reads the key offsets off the encoder's readout: inputs='readout'")
        self.goal_offsets = bool(goal_offsets)
        self.agent, self.touch = agent, encoder.to(agent.device).eval().requires_grad_(False)
        self.device, self.config, self.precision = agent.device, agent.config, agent.precision
        self.fitted = False
        self.inputs = inputs
        self.pose_inputs = bool(pose_inputs)
        self.input_size = touch_input_size(encoder, inputs, pose_inputs)
        self.key_positions_mm = None
        if key_positions_mm is not None:
            positions = np.asarray(key_positions_mm, dtype=np.float32)
            if positions.shape != (encoder.keys, 2):
                raise ValueError(
                    f"key_positions_mm needs one (x, y) per goal key, shape {(encoder.keys, 2)}, "
                    f"got {positions.shape}"
                )
            if not np.isfinite(positions).all():
                raise ValueError(f"key_positions_mm must be finite, got {positions.tolist()}")
            self.key_positions_mm = positions

    def goals(self, goals: np.ndarray) -> np.ndarray:
        """Goal one-hots (..., keys), followed by the goal key's standardised position if known."""
        if self.key_positions_mm is None:
            return goals
        positions = self.touch.standardise(self.key_positions_mm)
        return np.concatenate([goals, (goals @ positions).astype(np.float32)], axis=-1)  # zeros: no goal

    def encode(self, images: np.ndarray, labels: np.ndarray | None = None) -> np.ndarray:
        """What the agent learns on, of a batch of images: the encoder's features or its readout,
        followed with ``pose_inputs`` by the standardised pose of the frames' ``labels`` (B, >= 3)."""
        vectors = self.touch.encode(images) if self.inputs == "features" else self.touch.read(images)
        if not self.pose_inputs:
            return vectors
        poses = None if labels is None else np.asarray(labels, dtype=np.float32)[:, :3]
        if poses is None or np.isnan(poses).any():
            raise ValueError("an agent with pose inputs needs the arm's pose of every frame it encodes")
        return np.concatenate([vectors, self.touch.standardise(poses)], axis=-1)

    def view(self, vectors: np.ndarray, goals: np.ndarray) -> np.ndarray:
        """What the learner sees of :meth:`encode`'s vectors (B, n) for these goal one-hots (B, keys):
        the vectors themselves, or with ``goal_offsets`` the readout with only the goal key's offset
        (zeros for no goal)."""
        if not self.goal_offsets:
            return vectors
        keys = self.touch.keys
        offsets = vectors[:, -2 * keys :].reshape(len(vectors), keys, 2)
        aimed = np.einsum("bk,bkd->bd", np.asarray(goals, dtype=np.float32)[:, :keys], offsets)
        return np.concatenate([vectors[:, : -2 * keys], aimed], axis=-1).astype(np.float32)

    def features(self, observation: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
        """The observation with its image replaced by :meth:`encode`'s vector (and its goal placed)."""
        poses = None
        if self.pose_inputs:
            if PROPRIO_KEY not in observation:
                raise ValueError(
                    f"this agent acts on the arm's pose (touch.pose_inputs), but the observation has no "
                    f"{PROPRIO_KEY!r}: make its environment with proprio=True (the proprio track)"
                )
            poses = np.asarray(observation[PROPRIO_KEY], dtype=np.float32)[None]
        goal = np.asarray(observation["desired_goal"], dtype=np.float32)
        return {
            **{name: value for name, value in observation.items() if name != PROPRIO_KEY},
            "observation": self.view(self.encode(observation["observation"][None], poses), goal[None])[0],
            "desired_goal": self.goals(goal),
        }

    def policy_action(self, observation: dict, *args, **kwargs):
        return self.agent.policy_action(self.features(observation), *args, **kwargs)

    def random_action(self, space, rng: np.random.Generator):
        """The wrapped agent's random action of the start steps."""
        return self.agent.random_action(space, rng)

    def sample(self, buffer, batch_size: int, rng: np.random.Generator) -> dict[str, np.ndarray]:
        """A batch of the replay's transitions (features, with the encoder's cache)."""
        return buffer.sample(batch_size, rng)

    def update(self, batch: dict[str, np.ndarray]) -> dict[str, float]:
        """An update of the wrapped agent; poses in the batch are standardised as the encoder's targets."""
        views = {name: self.view(batch[name], batch["goals"]) for name in ("images", "next_images")}
        batch = {**batch, **views, "goals": self.goals(batch["goals"])}
        if "poses" in batch:
            batch["poses"] = self.touch.standardise(batch["poses"])
            batch["next_poses"] = self.touch.standardise(batch["next_poses"])
        return self.agent.update(batch)

    def end_epoch(self) -> None:
        self.agent.end_epoch()

    def fit(self, encoder: TouchEncoder) -> None:
        """Take a fitted encoder's weights."""
        self.touch.load_state_dict(encoder.state_dict())
        self.fitted = True

    def state_dict(self) -> dict:
        return {**self.agent.state_dict(), "touch": self.touch.state_dict(), "touch_fitted": self.fitted}

    def load_state_dict(self, state: dict) -> None:
        if "touch" not in state:
            raise ValueError("checkpoint lacks the touch encoder of a touch-encoder run")
        self.agent.load_state_dict({k: v for k, v in state.items() if k not in ("touch", "touch_fitted")})
        self.touch.load_state_dict(state["touch"])
        self.fitted = bool(state.get("touch_fitted", True))

    def policy_state_dict(self) -> dict:
        return {**self.agent.policy_state_dict(), "touch": self.touch.state_dict()}

    def load_policy_state_dict(self, state: dict) -> None:
        if "touch" not in state:
            raise ValueError("policy snapshot lacks the touch encoder of a touch-encoder run")
        self.agent.load_policy_state_dict({k: v for k, v in state.items() if k != "touch"})
        self.touch.load_state_dict(state["touch"])


def touch_input_size(
    encoder: TouchEncoder, inputs: str, pose_inputs: bool = False, goal_offsets: bool = False
) -> int:
    """Length of the vectors a :class:`TouchAgent` with these ``inputs`` (and pose inputs) encodes, or
    with ``goal_offsets`` those it learns on (:meth:`TouchAgent.view`)."""
    size = encoder.features_size if inputs == "features" else encoder.readout_size
    return size + 3 * bool(pose_inputs) - (2 * encoder.keys - 2) * bool(goal_offsets)


def feature_space(
    observation_space: gym.spaces.Dict, features: int, goal_positions: bool = False
) -> gym.spaces.Dict:
    """The observation space with the image replaced by ``features`` float32 features (and, with
    ``goal_positions``, the goal one-hot followed by the goal key's standardised x and y); the arm's
    pose, if the observation has it, goes into the features (:meth:`TouchAgent.encode`)."""
    spaces = {name: space for name, space in observation_space.spaces.items() if name != PROPRIO_KEY}
    spaces["observation"] = gym.spaces.Box(-np.inf, np.inf, (features,), dtype=np.float32)
    if goal_positions:
        keys = observation_space["desired_goal"].shape[0]
        spaces["desired_goal"] = gym.spaces.Box(-np.inf, np.inf, (keys + 2,), dtype=np.float32)
    return gym.spaces.Dict(spaces)
