"""A key-graph planner: a model-based agent that learns from touch alone.

Where DQN learns a value for every pair of frame and goal, the planner learns
two small models from its run's own experience and plans on them:

* **a key reader**, a small CNN that names the key under the sensor from a
  frame (the task's keys and a last class, *nothing*: a cell off the keys).
  Its labels are the achieved goals of presses (an observation: a press does
  not move, so the frame it was chosen on shows the key it pressed; a press
  that achieves nothing and goes on shows no key), and the frames before a
  press, labelled by **backtracking**: from the pressed key, back through the
  episode's moves on the key graph, as long as the graph names one class with
  probability at least ``accept``.
* **a key graph**, ``P(state' | state, move)``, counted over the replay's
  moves from the reader's (or the labels') class probabilities of both
  frames. Its states are the keys, and for a frame that reads *nothing*, the
  key and the move it came by (:func:`state_classes`): every cell off the
  keys reads alike, and without that memory a plan circles through them (from
  X down to nothing, as if that nothing were the one under K, and back).

It acts on a belief over states, the reader's probabilities filtered through
the graph and the previous action (a discrete Bayes filter, which keeps the
belief of the episode in progress), by QMDP: PRESS is worth the belief that
the goal is under the sensor, a move the discounted value of where the graph
says it leads (value iteration per goal, ``gamma``; ``test_gamma`` in test
episodes and typing); a move the graph has not seen from the believed state
is worth the discount (optimism, so that the run
explores it). ``repeat_penalty`` takes value off an action already taken from
the believed state in the episode (in the generic *nothing*, an episode's start
off the keys, only after ``free_repeats``: there repeating the best move is a
straight line out, until it meets the workspace's edge). With ``outcome_memory``
a test episode plans on the graph with each move it took from a believed state
leading where it led: a move the graph makes a draw (a misread key, the
workspace's edge) is not drawn again from the same state.
Exploring, it acts at random with the probability ``epsilon``.

The generic *nothing* is every cell off the keys at once, and its pooled moves reach each key beside
them with some probability: value iteration reads that as a draw made again at every step, and a plan
through it looks shorter than any real path. ``lost_value`` gives a move into it only that share of
its value (its own moves keep theirs). ``backtrack_prior`` reads the backtracked belief with each
state's occupancy in the replay, so that the many rarely occupied states off the keys do not outvote
the key beside them.

Everything it learns from is in the observation dictionary (frames, previous
actions, achieved goals): the ``tactile`` track. It knows the actions'
documented meaning (four moves and a press), not the layout.

On the continuous tasks it acts with the same five actions, as continuous
ones (:func:`continuous_actions`): a move of ``move`` (a share of the task's
largest) along x or y with a light tap at ``sense_depth``, and a press, a
tap at the deepest depth without a move. Its graph's moves are then no longer
one key each (the start is anywhere, and the keys' pitch is not the move's),
which its soft counts and its belief filter carry as they are. ``press_reading``
refuses a test episode's press where the frame under the sensor, read alone, does
not show the goal: the belief starts again from that frame; without ``first_press``
a test episode does not press on its first frame, and moves first.
"""

from __future__ import annotations

import itertools

import gymnasium as gym
import numpy as np
import torch
from torch import nn
from torch.nn import functional as F

from tactile_braille.agents.common import Agent, spaces_sizes
from tactile_braille.agents.config import PlannerConfig
from tactile_braille.agents.replay import EpisodeSteps
from tactile_braille.envs.tasks import DISCRETE_ACTIONS
from tactile_braille.supervised.fit import adam

PRESS = DISCRETE_ACTIONS.index("PRESS")
MOVES = PRESS
"""The moves (UP, DOWN, LEFT, RIGHT) come before PRESS in the action order."""


def continuous_actions(move: float, sense_depth: float) -> np.ndarray:
    """The planner's actions on a continuous task, (5, 3) float32 in the normalised ``(dx, dy, depth)``:
    the four moves, ``move`` along the work frame's -x, +x, +y and -y (up, down, left and right on the
    keyboard, as the discrete UP, DOWN, LEFT and RIGHT) with a tap at ``sense_depth``, then PRESS, the
    deepest tap (depth 1) where the sensor is.
    """
    actions = np.zeros((len(DISCRETE_ACTIONS), 3), np.float32)
    actions[:MOVES, :2] = [(-move, 0.0), (move, 0.0), (0.0, move), (0.0, -move)]
    actions[:MOVES, 2] = sense_depth
    actions[PRESS, 2] = 1.0
    return actions


class KeyReader(nn.Module):
    """A small CNN: the class logits (keys, then *nothing*) of 100x100 uint8 frames (B, 1, H, W); ``hidden``:
    its dense layers' units."""

    def __init__(self, classes: int, hidden: tuple[int, ...] = (128,)) -> None:
        super().__init__()
        self.convolutions = nn.Sequential(
            nn.AvgPool2d(2), nn.Conv2d(1, 16, 5, 2), nn.ReLU(), nn.Conv2d(16, 32, 3, 2), nn.ReLU(),
            nn.Conv2d(32, 32, 3, 2), nn.ReLU(), nn.Flatten(),
        )  # fmt: skip
        sizes = (self.convolutions(torch.zeros(1, 1, 100, 100)).shape[1], *hidden)
        layers: list[nn.Module] = []
        for size_in, size_out in itertools.pairwise(sizes):
            layers += [nn.Linear(size_in, size_out), nn.ReLU()]
        self.head = nn.Sequential(*layers, nn.Linear(sizes[-1], classes))

    def forward(self, frames: torch.Tensor) -> torch.Tensor:
        return self.head(self.convolutions(frames.float() / 255.0))


class KeyGraph(nn.Module):
    """The learnt moves between states (:func:`state_classes`): ``moves[s, m, t]`` = P(state t after
    move m from state s), ``visits[s, m]`` the (soft) moves counted, and ``prior[c]`` each class's share
    of the labels."""

    def __init__(self, keys: int, entry: bool = False) -> None:
        super().__init__()
        states = len(state_classes(keys, entry))
        self.register_buffer("moves", torch.full((states, MOVES, states), 1.0 / states))
        self.register_buffer("visits", torch.zeros(states, MOVES))
        self.register_buffer("prior", torch.full((keys + 1,), 1.0 / (keys + 1)))


def state_classes(keys: int, entry: bool = False) -> np.ndarray:
    """The class each planning state reads: the ``keys`` key states, then *nothing* (an episode's
    start or after nothing), then nothing reached from key k by move m (state ``keys + 1 + k * 4 + m``):
    cells off the keys all read alike, and the key and the move before one tell them apart.

    With ``entry`` (:func:`place_entry`): each class (the keys, then nothing) five times over, as
    reached by no move (an episode's start, a press) and by each of the four moves (state ``c * 5 + e``).
    """
    if entry:
        return np.repeat(np.arange(keys + 1), MOVES + 1)
    return np.r_[np.arange(keys), np.full(1 + keys * MOVES, keys)]


def place_entry(reading: np.ndarray, action: int | None) -> np.ndarray:
    """A frame's distribution over the ``entry`` states (:func:`state_classes`) from its class
    probabilities and the action that led to it (None: an episode's first frame): on the continuous
    tasks a move need not leave the key, and how the sensor came onto a key says which part of it the
    sensor is on."""
    entry = 0 if action is None or action == PRESS else action + 1
    state = np.zeros(len(reading) * (MOVES + 1))
    state[entry :: MOVES + 1] = reading
    return state


def place(reading: np.ndarray, before: np.ndarray | None, action: int, memory: bool = True) -> np.ndarray:
    """A frame's state distribution from its class probabilities (keys, then nothing), the state
    distribution of the frame before it (None: an episode's first) and the action between; without
    ``memory`` every frame that reads nothing is in the one state *nothing*. A move from nothing to
    nothing is in *nothing*."""
    keys = len(reading) - 1
    state = np.zeros(keys + 1 + keys * MOVES)
    state[:keys] = reading[:keys]
    nothing = reading[keys]
    if before is None or not memory:
        state[keys] = nothing
    elif action == PRESS:  # a press on nothing stays where it was
        off_keys = before[keys:]
        total = off_keys.sum()
        if total > 0:
            state[keys:] = nothing * off_keys / total
        else:
            state[keys] = nothing
    else:
        state[keys + 1 + np.arange(keys) * MOVES + action] = nothing * before[:keys]
        state[keys] = nothing * before[keys:].sum()
    return state


class PlannerAgent(Agent):
    """The key-graph planner.

    Args:
        observation_space: the task's Dict observation space (tactile images).
        action_space: its ``Discrete(5)`` action space (four moves, then PRESS), or a continuous
            task's ``Box(-1, 1, (3,))``, in which it takes :func:`continuous_actions`.
        config: hyperparameters.
        device: torch device of the reader.
        precision: ``"fp32"`` or ``"bf16"`` (autocast in the reader's update).
    """

    policy_parts = ("reader", "graph")
    checkpointed = ("reader", "graph", "optimiser")

    @classmethod
    def replay_extras(cls, config: PlannerConfig) -> tuple:
        """No batch entries (it reads the replay's episodes itself), but checkpoints keep their steps."""
        return (EpisodeSteps(),)

    def __init__(
        self,
        observation_space: gym.spaces.Dict,
        action_space: gym.spaces.Discrete,
        config: PlannerConfig | None = None,
        device: str = "cpu",
        precision: str = "fp32",
    ) -> None:
        super().__init__(device, precision)
        discrete = isinstance(action_space, gym.spaces.Discrete) and int(action_space.n) == len(
            DISCRETE_ACTIONS
        )
        continuous = isinstance(action_space, gym.spaces.Box) and action_space.shape == (3,)
        if not (discrete or continuous):
            raise ValueError(
                f"the planner needs the discrete tasks' Discrete(5) actions or the continuous tasks' "
                f"Box(-1, 1, (3,)), got {action_space}"
            )
        self.config = config or PlannerConfig()
        if observation_space["observation"].shape != (100, 100, 1):
            raise ValueError(
                f"the planner reads single 100x100 tactile images, got {observation_space['observation']}"
            )
        config = self.config
        self.continuous = None if discrete else continuous_actions(config.move, config.sense_depth)
        self.actions = len(DISCRETE_ACTIONS)
        self.keys, _ = spaces_sizes(observation_space)
        self.classes = self.keys + 1  # the keys, then nothing (a cell off the keys)
        entry = self.config.entry_memory
        self.state_class = state_classes(self.keys, entry)
        # The state of an episode's start off the keys, where the repeat penalty does not apply.
        self.start_nothing = self.keys * (MOVES + 1) if entry else self.keys
        # The states ``lost_value`` discounts: the generic nothing; with entry states, all of nothing's.
        self.lost_states = np.flatnonzero(self.state_class == self.keys) if entry else np.array([self.keys])
        self.reader = KeyReader(self.classes, self.config.hidden).to(self.device)
        self.graph = KeyGraph(self.keys, entry).to(self.device)
        self.optimiser = adam(self.reader.parameters(), self.config.learning_rate, self.config.adam_eps)
        self.label_frames = np.zeros(0, dtype=np.int64)  # frame slots of the replay with a class
        self.label_classes = np.zeros(0, dtype=np.int64)
        self.fitted_size = -1  # the replay's size at the last refit (-1: none since made or restored)
        self.refits = 0
        self._beliefs: dict[bool, np.ndarray] = {}  # the belief of each stream's episode (train, test)
        self._readings: dict[bool, np.ndarray] = {}  # the reading of each stream's last frame
        self._taken: dict[bool, np.ndarray] = {}  # the actions taken from each believed state in it
        self._outcomes: dict[tuple[int, int], int] = {}  # ``outcome_memory``: the test episode's moves
        self._episode_plans: dict[int, tuple[np.ndarray, np.ndarray]] = {}  # its moves, values by goal
        self._plan()

    # ------------------------------------------------------------ acting
    def epsilon(self, step: int) -> float:
        """Exploration rate after ``step`` environment steps (linear decay)."""
        config = self.config
        fraction = min(step / max(config.epsilon_decay_steps, 1), 1.0)
        return config.epsilon_start + fraction * (config.epsilon_end - config.epsilon_start)

    @torch.no_grad()
    def read(self, frames: np.ndarray, batch_size: int = 512) -> np.ndarray:
        """Class probabilities (N, classes) of uint8 frames (N, 1, H, W) or (N, H, W, 1)."""
        frames = np.asarray(frames)
        if frames.ndim == 4 and frames.shape[-1] == 1 and frames.shape[1] != 1:
            frames = np.moveaxis(frames, -1, 1)
        self.reader.eval()
        out = [
            F.softmax(self.reader(torch.as_tensor(frames[i : i + batch_size], device=self.device)), -1)
            for i in range(0, len(frames), batch_size)
        ]
        return torch.cat(out).float().cpu().numpy() if out else np.zeros((0, self.classes), np.float32)

    def belief(self, observation: dict[str, np.ndarray], stream: bool = False) -> np.ndarray:
        """The belief over states after ``observation``: the reader's probabilities placed after the
        last belief of ``stream`` (:func:`place`), or, with ``filter``, that belief carried by the graph
        through the previous action and weighed by the reading (a Bayes filter)."""
        reading = self.read(observation["observation"][None])[0].astype(np.float64)
        previous = np.asarray(observation["previous_action"])
        last = self._beliefs.get(stream)
        new_episode = not previous.any() or last is None
        if new_episode:
            self._taken[stream] = np.zeros((len(self.state_class), self.actions))
            belief = self._place(reading, None, None)
        elif self.config.filter:
            action = int(self.action_indices(previous[None])[0])
            carried = last if action == PRESS else last @ self._moves[:, action, :]
            belief = (reading / self._prior)[self.state_class] * carried
        else:
            belief = self._place(reading, last, int(self.action_indices(previous[None])[0]))
        belief = belief / max(belief.sum(), 1e-300)
        if not stream and self.config.outcome_memory:
            self._remember_outcome(None if new_episode else last, previous, belief)
        self._beliefs[stream] = belief
        self._readings[stream] = reading
        return belief

    def _place(self, reading: np.ndarray, before: np.ndarray | None, action: int | None) -> np.ndarray:
        """The state distribution of a frame (:func:`place`, or :func:`place_entry`) after the action
        index ``action``."""
        action = None if action is None else int(action)
        if self.config.entry_memory:
            return place_entry(reading, action)
        return place(reading, before, PRESS if action is None else action, self.config.nothing_memory)

    def _remember_outcome(self, last: np.ndarray | None, previous: np.ndarray, belief: np.ndarray) -> None:
        """``outcome_memory``: note the state the test stream's last move led to from the state believed
        before it (``last`` None: a new episode, which forgets them all)."""
        if last is None:
            self._outcomes, self._episode_plans = {}, {}
            return
        action = int(self.action_indices(previous[None])[0])
        if action == PRESS:
            return
        seen = (int(last.argmax()), action)
        outcome = int(belief.argmax())
        if self._outcomes.get(seen) != outcome:
            self._outcomes[seen] = outcome
            self._episode_plans = {}  # replanned with it

    def _gamma(self, episode: bool) -> float:
        """The discount of a plan: ``test_gamma`` in test episodes and typing where it is set."""
        test = self.config.test_gamma
        return test if episode and test is not None else self.config.gamma

    def _model(self, goal: int, episode: bool) -> tuple[np.ndarray, np.ndarray]:
        """The moves and the goal's values a plan acts on: the graph's, or in the test episode with
        ``outcome_memory`` the graph with each move already seen from a state leading where it led."""
        if not (episode and self._outcomes):
            return self._moves, (self._test_values if episode else self._values)[goal]
        if goal not in self._episode_plans:
            moves = self._moves.copy()
            for (state, move), outcome in self._outcomes.items():
                moves[state, move] = 0.0
                moves[state, move, outcome] = 1.0
            rewards = (self.state_class == goal).astype(np.float64)[None]
            self._episode_plans[goal] = (moves, self._value_iteration(moves, rewards, self._gamma(True))[0])
        return self._episode_plans[goal]

    def action_values(self, belief: np.ndarray, goal: int, episode: bool = False) -> np.ndarray:
        """QMDP values of the actions under ``belief`` (over states) for the goal key ``goal``: the
        moves', then PRESS's (the belief on the goal); ``episode``: on the test episode's model
        (:meth:`_model`)."""
        gamma = self._gamma(episode)
        graph, values = self._model(goal, episode)
        moves = gamma * np.einsum("s,smt,t->m", belief, graph, values)
        if self.config.optimism:
            seen = belief @ (self._visits >= 1.0)
            moves = np.where(seen >= 0.5, moves, gamma)
        return np.append(moves, belief[self.state_class == goal].sum())

    def policy_action(
        self,
        observation: dict,
        step: int,
        explore: bool,
        rng: np.random.Generator,
        deterministic: bool = False,
    ) -> int | np.ndarray:
        """Epsilon-greedy on the QMDP values exploring, else with ``test_epsilon``; 0 if ``deterministic``.
        On a continuous task the chosen action as its :func:`continuous_actions` row."""
        belief = self.belief(observation, stream=explore)
        state = int(belief.argmax())
        taken = self._taken_from(explore, state)
        epsilon = 0.0 if deterministic else (self.epsilon(step) if explore else self.config.test_epsilon)
        if rng.random() < epsilon:
            action = self._random_index(rng)
        else:
            goal = int(np.argmax(observation["desired_goal"]))
            values = self.action_values(belief, goal, episode=not explore)
            action = int((values - self.config.repeat_penalty * taken).argmax())
            test_press = action == PRESS and not explore
            if test_press and (self._unread_goal(goal) or self._first_frame(observation)):
                belief, state, taken = self._restart(observation)  # from the frame, and no press
                values = self.action_values(belief, goal, episode=True)
                values[PRESS] = -np.inf
                action = int((values - self.config.repeat_penalty * taken).argmax())
        self._taken[explore][state, action] += 1
        return self._as_action(action)

    def _unread_goal(self, goal: int) -> bool:
        """With ``press_reading``: whether the test stream's last frame, read alone, gives the goal key
        less than that probability (so that a press there is refused)."""
        least = self.config.press_reading
        return least is not None and self._readings[False][goal] < least

    def _first_frame(self, observation: dict) -> bool:
        """Without ``first_press``: whether ``observation`` is its episode's first frame (no action yet)."""
        return not self.config.first_press and not np.asarray(observation["previous_action"]).any()

    def _taken_from(self, stream: bool, state: int) -> np.ndarray:
        """The counts of the actions taken from ``state`` in ``stream``'s episode that the repeat
        penalty weighs (in the generic nothing, only those past ``free_repeats``)."""
        taken = self._taken[stream][state]
        if state == self.start_nothing:  # the generic nothing: free repeats, or all (a straight line out)
            free = self.config.free_repeats
            taken = np.zeros_like(taken) if free is None else np.maximum(taken - free, 0.0)
        return taken

    def _restart(self, observation: dict) -> tuple[np.ndarray, int, np.ndarray]:
        """The test stream's belief started again from its last frame's reading, placed after the
        previous action as at an episode's start (``press_reading``): the belief, its state and the
        actions taken from that state."""
        previous = np.asarray(observation["previous_action"])
        action = int(self.action_indices(previous[None])[0]) if previous.any() else None
        belief = self._place(self._readings[False], None, action)
        belief = belief / max(belief.sum(), 1e-300)
        self._beliefs[False] = belief
        state = int(belief.argmax())
        return belief, state, self._taken_from(False, state)

    def random_action(self, space: gym.Space, rng: np.random.Generator) -> int | np.ndarray:
        """One of its five actions at random (the start steps'), as its exploration draws them."""
        return self._as_action(self._random_index(rng))

    def _as_action(self, index: int) -> int | np.ndarray:
        """The environment's action for an action index: itself, or its :func:`continuous_actions` row."""
        return index if self.continuous is None else self.continuous[index].copy()

    def _random_index(self, rng: np.random.Generator) -> int:
        """A random action index: uniform, or PRESS with the probability ``explore_press``."""
        if self.config.explore_press is None:
            return int(rng.integers(len(DISCRETE_ACTIONS)))
        return PRESS if rng.random() < self.config.explore_press else int(rng.integers(MOVES))

    def action_indices(self, actions: np.ndarray) -> np.ndarray:
        """The planner's action index (moves, then PRESS) of each of ``actions``: discrete indices (N,),
        one-hot previous actions (N, 5), or continuous ones (N, 3), which must be its own.

        Raises:
            ValueError: a continuous action that is none of :func:`continuous_actions` (a forced final
                press: the planner learns only from its own actions).
        """
        actions = np.asarray(actions)
        if self.continuous is None:
            return actions.argmax(-1) if actions.ndim == 2 else actions.astype(np.int64)
        distance = np.abs(actions[:, None, :] - self.continuous[None]).max(-1)
        index = distance.argmin(-1)
        strangers = distance[np.arange(len(actions)), index] > 1e-4
        if strangers.any():
            raise ValueError(
                f"the planner acts with its own {len(self.continuous)} continuous actions "
                f"{self.continuous.tolist()}, got {actions[strangers][:3].tolist()}: run it without "
                f"final_press"
            )
        return index

    # ------------------------------------------------------------ learning
    def sample(self, buffer, batch_size: int, rng: np.random.Generator) -> dict[str, np.ndarray]:
        """A batch of labelled frames for the reader, the models refitted from ``buffer`` first when
        ``refit_every`` transitions came since the last refit."""
        if self.fitted_size < 0 or buffer.size - self.fitted_size >= self.config.refit_every:
            self.refit(buffer)
        if len(self.label_frames) == 0:
            return {"frames": np.zeros((0, 1, 100, 100), np.uint8), "classes": np.zeros(0, np.int64)}
        index = rng.integers(len(self.label_frames), size=min(batch_size, len(self.label_frames)))
        batch = {
            "frames": buffer.store.observations(self.label_frames[index]),
            "classes": self.label_classes[index],
        }
        return batch

    def update(self, batch: dict[str, np.ndarray]) -> dict[str, float]:
        """One gradient step of the reader's cross-entropy on labelled frames."""
        if len(batch["classes"]) == 0:
            return {}
        t = self.tensors(batch)
        self.reader.train()
        with self.autocast():
            loss = F.cross_entropy(self.reader(t["frames"]).float(), t["classes"])
        self.optimiser.zero_grad(set_to_none=True)
        loss.backward()
        self.optimiser.step()
        return {"losses/reader_loss": loss.item(), "charts/labelled_frames": float(len(self.label_frames))}

    def refit(self, buffer) -> None:
        """Refit the graph, the labels and the values from the replay's transitions."""
        transitions = replay_order(buffer)
        self.fitted_size, self.refits = buffer.size, self.refits + 1
        if len(transitions) == 0:
            return
        this, after = buffer.frame_index[transitions, 0], buffer.frame_index[transitions, 1]
        actions = self.action_indices(buffer.actions[transitions])
        achieved, dones = buffer.achieved[transitions].astype(np.int64), buffer.dones[transitions] > 0
        frames, rows = np.unique(np.concatenate([this, after]), return_inverse=True)
        row_this, row_after = rows[: len(this)], rows[len(this) :]
        probabilities = self.read(buffer.store.observations(frames)).astype(np.float64)

        pressed = actions == PRESS
        anchors = np.full(len(frames), -1)
        # A press labels the frame it was chosen on (it does not move). A press of no goal key shows
        # nothing: on the discrete tasks it goes on (a cell off the keys), on the continuous ones it may
        # also end the episode (a key outside the task's).
        anchors[row_this[pressed]] = np.where(achieved[pressed] >= 0, achieved[pressed], self.keys)
        known = anchors >= 0
        prior = np.bincount(anchors[known], minlength=self.classes) + 1.0
        prior /= prior.sum()
        remaining = buffer.remaining[transitions].astype(np.int64)
        firsts = np.r_[True, remaining[:-1] == 0]  # each episode's first transition
        ends = np.flatnonzero(dones & pressed & (achieved >= 0))
        starts = episode_starts(remaining, ends)
        labels = anchors
        for _ in range(self.config.refit_passes):  # the graph from the labels, the labels from the graph
            labelled = labels >= 0
            probabilities[labelled] = np.eye(self.classes)[labels[labelled]]
            states_this, states_after = placed_states(probabilities, row_this, row_after, actions, firsts,
                                                      self._place)  # fmt: skip
            counts = np.zeros_like(self._moves)
            for move in range(MOVES):
                chosen = actions == move
                counts[:, move, :] = states_this[chosen].T @ states_after[chosen]
            off_keys = len(self.state_class) if self.config.entry_memory else self.keys  # none pooled
            moves = graph_moves(counts, off_keys, self.config.graph_prior, self.config.backoff)
            occupancy = states_this.sum(0) + 1e-3 if self.config.backtrack_prior else None
            labels = backtrack(moves, self.state_class, anchors, row_this, actions, achieved, starts, ends,
                               self.config.sharpen, self.config.accept, occupancy)  # fmt: skip
        self.graph.moves.copy_(torch.as_tensor(moves))
        visits = counts.sum(-1)
        visits[off_keys:] = visits[off_keys:].sum(0)  # a state off the keys borrows the others' moves
        self.graph.visits.copy_(torch.as_tensor(visits))
        self.graph.prior.copy_(torch.as_tensor(prior))
        labelled = np.flatnonzero(labels >= 0)
        self.label_frames, self.label_classes = frames[labelled], labels[labelled]
        self._plan()

    def _plan(self) -> None:
        """Value iteration per goal on the graph: ``values[g, s]``, pressing worth 1 on the goal key."""
        self._moves = self.graph.moves.double().cpu().numpy()
        self._visits = self.graph.visits.double().cpu().numpy()
        self._prior = self.graph.prior.double().cpu().numpy()
        rewards = (np.arange(self.keys)[:, None] == self.state_class[None]).astype(np.float64)
        self._values = self._value_iteration(self._moves, rewards, self._gamma(False))
        test = self._gamma(True)
        same = test == self._gamma(False)
        self._test_values = self._values if same else self._value_iteration(self._moves, rewards, test)
        self._outcomes, self._episode_plans = {}, {}

    def _value_iteration(self, moves: np.ndarray, rewards: np.ndarray, gamma: float) -> np.ndarray:
        """Values (goals, states) on ``moves`` (states, moves, states) of pressing worth ``rewards``
        (goals, states), discounted by ``gamma``, ``planning_sweeps`` sweeps."""
        values = rewards.copy()
        lost = self.config.lost_value
        for _ in range(self.config.planning_sweeps):
            ahead = values
            if lost is not None:  # the generic nothing, entered from elsewhere
                ahead = values.copy()
                ahead[:, self.lost_states] *= lost
            backed = gamma * np.einsum("smt,gt->gsm", moves, ahead).max(-1)
            if lost is not None:  # acting from it, its own moves as they are
                backed[:, self.lost_states] = gamma * np.einsum(
                    "smt,gt->gsm", moves[self.lost_states], values
                ).max(-1)
            values = np.maximum(rewards, backed)
        return values

    def load_state_dict(self, state: dict) -> None:
        super().load_state_dict(state)
        self.fitted_size = -1  # the labels are the replay's: read again at the next update
        self._plan()

    def load_policy_state_dict(self, state: dict) -> None:
        super().load_policy_state_dict(state)
        self._plan()


def graph_moves(counts: np.ndarray, keys: int, prior: float, backoff: float) -> np.ndarray:
    """``P(state' | state, move)`` from soft counts (states, moves, states): a key state's with
    ``prior`` pseudo-counts spread evenly; a state off the keys' with ``backoff`` pseudo-counts spread as
    the moves of all states off the keys together (it is seen more rarely than any key)."""
    moves = counts + prior / counts.shape[-1]
    pooled = counts[keys:].sum(0) + prior / counts.shape[-1]
    pooled /= pooled.sum(-1, keepdims=True)
    moves[keys:] = counts[keys:] + backoff * pooled
    return moves / moves.sum(-1, keepdims=True)


def placed_states(
    probabilities: np.ndarray,
    row_this: np.ndarray,
    row_after: np.ndarray,
    actions: np.ndarray,
    firsts: np.ndarray,
    placing,
) -> tuple[np.ndarray, np.ndarray]:
    """The state distributions of each transition's two frames, in replay order (``firsts`` marks each
    episode's first transition); ``placing(reading, before, action)`` places a frame (action None: an
    episode's first): the agent's (:func:`place` or :func:`place_entry`)."""
    states_this, states_after = [], []
    state = None
    for step, action in enumerate(actions):
        if firsts[step]:  # the first transition is always one
            state = placing(probabilities[row_this[step]], None, None)
        states_this.append(state)
        state = placing(probabilities[row_after[step]], state, int(action))
        states_after.append(state)
    return np.array(states_this), np.array(states_after)


def backtrack(
    moves: np.ndarray,
    state_class: np.ndarray,
    anchors: np.ndarray,
    rows: np.ndarray,
    actions: np.ndarray,
    achieved: np.ndarray,
    starts: np.ndarray,
    ends: np.ndarray,
    sharpen: float,
    accept: float,
    occupancy: np.ndarray | None = None,
) -> np.ndarray:
    """Each frame's class: its own press's (``anchors``, -1 for none), or one read back from the key
    its episode pressed.

    Args:
        moves: the graph ``P(state' | state, move)``, (states, moves, states).
        state_class: the class each state reads (:func:`state_classes`).
        anchors: the class of each frame a press was chosen on, -1 elsewhere.
        rows: each transition's first frame (an index into ``anchors``).
        actions, achieved: each transition's action and pressed key (-1: none).
        starts, ends: the first and the pressing last transition of each episode that pressed a key.
        sharpen: the graph is read as ``moves ** sharpen``, renormalised.
        accept: the labelling of an episode stops, going back, where no class has this probability.
        occupancy: how often each state is occupied (states,), the prior the backtracked belief is
            read with (``P(state | key pressed later) ∝ P(key pressed later | state) P(state)``); None:
            every state alike.
    """
    labels = anchors.copy()
    sharp = moves**sharpen
    sharp /= sharp.sum(-1, keepdims=True)
    classes = int(state_class.max()) + 1
    collapse = np.eye(classes)[state_class]  # (states, classes)
    for start, end in zip(starts, ends, strict=True):
        belief = (state_class == achieved[end]) / np.sum(state_class == achieved[end])  # the key pressed
        for step in range(end - 1, start - 1, -1):
            if actions[step] != PRESS:  # a press on nothing stays where it was
                belief = sharp[:, actions[step], :] @ belief
            belief /= max(belief.sum(), 1e-300)
            read = belief @ collapse
            if occupancy is not None:
                weighed = belief * occupancy
                read = weighed @ collapse / max(weighed.sum(), 1e-300)
            if read.max() < accept:
                break
            if labels[rows[step]] < 0:
                labels[rows[step]] = int(read.argmax())
    return labels


def replay_order(buffer) -> np.ndarray:
    """The replay's transition slots, oldest first (its ring buffer unrolled)."""
    if buffer.size < buffer.capacity:
        return np.arange(buffer.size)
    return (np.arange(buffer.capacity) + buffer.next_slot) % buffer.capacity


def episode_starts(remaining: np.ndarray, ends: np.ndarray) -> np.ndarray:
    """The first transition of the episode of each transition in ``ends``, from the replay's
    ``remaining`` (steps after each transition in its episode) over transitions in order."""
    firsts = np.flatnonzero(np.r_[True, remaining[:-1] == 0])
    return firsts[np.searchsorted(firsts, ends, side="right") - 1]
