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
says it leads (value iteration per goal, ``gamma``); a move the graph has not
seen from the believed state is worth ``gamma`` (optimism, so that the run
explores it). ``repeat_penalty`` takes value off an action already taken from
the believed state in the episode (in the generic *nothing*, an episode's start
off the keys, only after ``free_repeats``: there repeating the best move is a
straight line out, until it meets the workspace's edge).
Exploring, it acts at random with the probability ``epsilon``.

The generic *nothing* is every cell off the keys at once, and its pooled moves reach each key beside
them with some probability: value iteration reads that as a draw made again at every step, and a plan
through it looks shorter than any real path. ``lost_value`` gives a move into it only that share of
its value (its own moves keep theirs). ``backtrack_prior`` reads the backtracked belief with each
state's occupancy in the replay, so that the many rarely occupied states off the keys do not outvote
the key beside them. ``reckon`` is dead reckoning off the keys on the discrete tasks: nothing placed by
the key it last left and the sum of the moves since (:func:`reckon_shifts`).

Everything it learns from is in the observation dictionary (frames, previous
actions, achieved goals): the ``tactile`` track. It knows the actions'
documented meaning (four moves and a press), not the layout.

On the continuous tasks it acts with the same five actions, as continuous
ones (:func:`continuous_actions`): a move of ``move`` (a share of the task's
largest) along x or y with a light tap at ``sense_depth``, and a press, a
tap at the deepest depth without a move. Its graph's moves are then no longer
one key each (the start is anywhere, and the keys' pitch is not the move's),
which its soft counts and its belief filter carry as they are. With
``move_press`` it has four more actions there: each move with a press at its
end, worth the belief that the move ends on the goal key (a known neighbour is
typed in one step, not a move and a press); the graph counts them as their
moves, and the key they press labels the frame they reach. ``press_accept`` ends a test episode's move
in a press where the graph is that sure the move reaches the goal, and ``locate`` aims test episodes'
steps with a metric key map (:mod:`~tactile_braille.agents.locator`); neither is in a preset (their
measurements: docs/agents.md, session 36). ``press_reading`` refuses a test episode's press where the
frame under the sensor, read alone, does not show the goal: the belief starts again from that frame;
without ``first_press`` a test episode does not press on its first frame, and moves first.
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
from tactile_braille.agents.locator import (
    KeyLocator,
    frame_pairs,
    key_targets,
    locate_action,
    locator_loss,
    press_points,
    press_separation,
)
from tactile_braille.envs.tasks import DISCRETE_ACTIONS
from tactile_braille.supervised.fit import adam

PRESS = DISCRETE_ACTIONS.index("PRESS")
MOVES = PRESS
"""The moves (UP, DOWN, LEFT, RIGHT) come before PRESS in the action order."""


def continuous_actions(move: float, sense_depth: float, move_press: bool = False) -> np.ndarray:
    """The planner's actions on a continuous task, (5, 3) float32 in the normalised ``(dx, dy, depth)``:
    the four moves, ``move`` along the work frame's -x, +x, +y and -y (up, down, left and right on the
    keyboard, as the discrete UP, DOWN, LEFT and RIGHT) with a tap at ``sense_depth``, then PRESS, the
    deepest tap (depth 1) where the sensor is; with ``move_press`` (9, 3): then the four moves again,
    each ending in a press (action ``PRESS + 1 + m`` is move ``m`` and a press).
    """
    actions = np.zeros((len(DISCRETE_ACTIONS) + MOVES * move_press, 3), np.float32)
    actions[:MOVES, :2] = [(-move, 0.0), (move, 0.0), (0.0, move), (0.0, -move)]
    actions[:MOVES, 2] = sense_depth
    actions[PRESS, 2] = 1.0
    if move_press:
        actions[PRESS + 1 :, :2] = actions[:MOVES, :2]
        actions[PRESS + 1 :, 2] = 1.0
    return actions


def graph_moves_of(actions: np.ndarray) -> np.ndarray:
    """The graph's move (0-3, or PRESS: none) each action index makes: a move and a press moves as the
    move alone."""
    actions = np.asarray(actions)
    return np.where(actions > PRESS, actions - PRESS - 1, actions)


def presses(actions: np.ndarray) -> np.ndarray:
    """Which action indices press: PRESS, and each move and press."""
    return np.asarray(actions) >= PRESS


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

    def __init__(self, keys: int, entry: bool = False, reckon: int = 0) -> None:
        super().__init__()
        states = len(state_classes(keys, entry, reckon))
        self.register_buffer("moves", torch.full((states, MOVES, states), 1.0 / states))
        self.register_buffer("visits", torch.zeros(states, MOVES))
        self.register_buffer("prior", torch.full((keys + 1,), 1.0 / (keys + 1)))


def state_classes(keys: int, entry: bool = False, reckon: int = 0) -> np.ndarray:
    """The class each planning state reads: the ``keys`` key states, then *nothing* (an episode's
    start or after nothing), then nothing reached from key k by move m (state ``keys + 1 + k * 4 + m``):
    cells off the keys all read alike, and the key and the move before one tell them apart.

    With ``entry`` (:func:`place_entry`): each class (the keys, then nothing) five times over, as
    reached by no move (an episode's start, a press) and by each of the four moves (state ``c * 5 + e``).

    With ``reckon`` (dead reckoning, :func:`reckon_shifts`): the keys, *nothing* (an episode's start off
    the keys, or lost), then nothing at each of :func:`reckon_offsets` from each key and from the
    episode's start (state ``keys + 1 + anchor * offsets + offset``, the start's anchor ``keys``): with
    ``reckon`` 1 the key-and-move states above, then the start's four.
    """
    if entry:
        return np.repeat(np.arange(keys + 1), MOVES + 1)
    anchors = keys + 1 if reckon else keys
    return np.r_[np.arange(keys), np.full(1 + anchors * max(len(reckon_offsets(reckon)), MOVES), keys)]


UNIT_MOVES = np.array([(-1, 0), (1, 0), (0, -1), (0, 1)])
"""Each move's documented step on a discrete task's grid, (rows, columns): UP, DOWN, LEFT, RIGHT."""


def reckon_offsets(reckon: int) -> np.ndarray:
    """The displacements (rows, columns) dead reckoning keeps, (n, 2): the four moves' own first, in
    their order, then the others up to ``reckon`` cells (by distance, then row and column); none for 0."""
    rest = [
        (r, c)
        for r in range(-reckon, reckon + 1)
        for c in range(-reckon, reckon + 1)
        if 1 < abs(r) + abs(c) <= reckon
    ]
    rest.sort(key=lambda d: (abs(d[0]) + abs(d[1]), d))
    return np.array([*UNIT_MOVES.tolist(), *rest]).reshape(-1, 2) if reckon else np.zeros((0, 2), int)


def reckon_shifts(keys: int, reckon: int) -> np.ndarray:
    """Where a frame that reads *nothing* is placed after each move from each state (states, moves), by
    dead reckoning (:func:`state_classes`): from a key or the start, at the move's offset from it; from
    nothing at an offset, at the offset plus the move's (back at the start: the start); further than
    ``reckon`` cells, or back on the key it left (that reads as a key), in the generic *nothing*."""
    offsets = reckon_offsets(reckon)
    index = {tuple(d): i for i, d in enumerate(offsets.tolist())}
    start = keys
    shifts = np.full((len(state_classes(keys, reckon=reckon)), MOVES), start)
    for anchor in range(keys + 1):
        base = keys + 1 + anchor * len(offsets)
        from_anchor = start if anchor == keys else anchor
        shifts[from_anchor] = base + np.arange(MOVES)
        for o, d in enumerate(offsets):
            for m, step in enumerate(UNIT_MOVES):
                target = tuple((d + step).tolist())
                if target in index:
                    shifts[base + o, m] = base + index[target]
    return shifts


def place_entry(reading: np.ndarray, action: int | None) -> np.ndarray:
    """A frame's distribution over the ``entry`` states (:func:`state_classes`) from its class
    probabilities and the action that led to it (None: an episode's first frame): on the continuous
    tasks a move need not leave the key, and how the sensor came onto a key says which part of it the
    sensor is on."""
    entry = 0 if action is None or action == PRESS else action + 1
    state = np.zeros(len(reading) * (MOVES + 1))
    state[entry :: MOVES + 1] = reading
    return state


def place(
    reading: np.ndarray,
    before: np.ndarray | None,
    action: int,
    memory: bool = True,
    carry: bool = False,
    shifts: np.ndarray | None = None,
) -> np.ndarray:
    """A frame's state distribution from its class probabilities (keys, then nothing), the state
    distribution of the frame before it (None: an episode's first) and the action between; without
    ``memory`` every frame that reads nothing is in the one state *nothing*. With ``carry`` a move from
    nothing to nothing keeps the key and the move by which the sensor left the keys (else: *nothing*).
    With ``shifts`` (:func:`reckon_shifts`) nothing after a move is where dead reckoning puts it."""
    keys = len(reading) - 1
    state = np.zeros(keys + 1 + keys * MOVES if shifts is None else len(shifts))
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
    elif shifts is not None:
        np.add.at(state, shifts[:, action], nothing * before)
    else:
        state[keys + 1 + np.arange(keys) * MOVES + action] = nothing * before[:keys]
        if carry:
            state[keys:] += nothing * before[keys:]
        else:
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
        if discrete and self.config.move_press:
            raise ValueError("move_press is for the continuous tasks: a discrete task has five actions")
        if discrete and self.config.locate:
            raise ValueError("locate maps a continuous task's moves: a discrete task moves a key at a time")
        if observation_space["observation"].shape != (100, 100, 1):
            raise ValueError(
                f"the planner reads single 100x100 tactile images, got {observation_space['observation']}"
            )
        config = self.config
        if discrete and config.press_accept is not None:
            raise ValueError("press_accept ends a continuous task's moves in a press: a discrete move cannot")
        with_presses = config.move_press or config.press_accept is not None  # their rows, to read them back
        self.continuous = (
            None if discrete else continuous_actions(config.move, config.sense_depth, with_presses)
        )
        self.actions = len(DISCRETE_ACTIONS) + MOVES * config.move_press
        self.keys, _ = spaces_sizes(observation_space)
        self.classes = self.keys + 1  # the keys, then nothing (a cell off the keys)
        entry, reckon = self.config.entry_memory, self.config.reckon
        if reckon and not discrete:
            raise ValueError("reckon counts a discrete task's grid cells: a continuous task has none")
        self.state_class = state_classes(self.keys, entry, reckon)
        self.shifts = reckon_shifts(self.keys, reckon) if reckon else None
        # The state of an episode's start off the keys, where the repeat penalty does not apply.
        self.start_nothing = self.keys * (MOVES + 1) if entry else self.keys
        # The states ``lost_value`` discounts: the generic nothing; with entry states, all of nothing's.
        self.lost_states = np.flatnonzero(self.state_class == self.keys) if entry else np.array([self.keys])
        self.reader = KeyReader(self.classes, self.config.hidden).to(self.device)
        self.graph = KeyGraph(self.keys, entry, reckon).to(self.device)
        self.optimiser = adam(self.reader.parameters(), self.config.learning_rate, self.config.adam_eps)
        self.label_frames = np.zeros(0, dtype=np.int64)  # frame slots of the replay with a class
        self.label_classes = np.zeros(0, dtype=np.int64)
        self.fitted_size = -1  # the replay's size at the last refit (-1: none since made or restored)
        self.refits = 0
        self._beliefs: dict[bool, np.ndarray] = {}  # the belief of each stream's episode (train, test)
        self._readings: dict[bool, np.ndarray] = {}  # the reading of each stream's last frame
        self._taken: dict[bool, np.ndarray] = {}  # the actions taken from each believed state in it
        self.locator = None
        if config.locate:  # the metric key map (tactile_braille.agents.locator), in the snapshots too
            self.locator = KeyLocator(self.keys, config.hidden).to(self.device)
            self.locator_optimiser = adam(
                self.locator.parameters(), config.locate_learning_rate, config.adam_eps
            )
            self.policy_parts = (*type(self).policy_parts, "locator")
            self.checkpointed = (*type(self).checkpointed, "locator", "locator_optimiser")
        self.pairs = np.zeros((0, 2), np.int64)  # the map's pairs of frame slots, their keys, their moves
        self.pair_keys = np.zeros((0, 2), np.int64)
        self.pair_moves = np.zeros((0, 2), np.float32)
        self._press_data: tuple | None = None  # the last refit's presses, for the map's targets
        # Where the map has the sensor in a test episode: None before it places it, False after a press
        # it aimed pressed nothing (the graph acts then).
        self._where: dict[bool, np.ndarray | bool | None] = {}
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
        if not previous.any() or last is None:  # a new episode
            self._taken[stream] = np.zeros((len(self.state_class), self.actions))
            belief = self._place(reading, None, None)
        elif self.config.filter:
            action = int(graph_moves_of(self.action_indices(previous[None]))[0])
            carried = last if action == PRESS else last @ self._moves[:, action, :]
            belief = (reading / self._prior)[self.state_class] * carried
        else:
            belief = self._place(reading, last, int(self.action_indices(previous[None])[0]))
        belief = belief / max(belief.sum(), 1e-300)
        self._beliefs[stream] = belief
        self._readings[stream] = reading
        return belief

    def _place(self, reading: np.ndarray, before: np.ndarray | None, action: int | None) -> np.ndarray:
        """The state distribution of a frame (:func:`place`, or :func:`place_entry`) after the action
        index ``action`` (a move and a press placed as its move)."""
        action = None if action is None else int(graph_moves_of(action))
        if self.config.entry_memory:
            return place_entry(reading, action)
        config = self.config
        return place(
            reading, before, PRESS if action is None else action, config.nothing_memory, config.nothing_carry,
            self.shifts,
        )  # fmt: skip

    def action_values(self, belief: np.ndarray, goal: int) -> np.ndarray:
        """QMDP values of the actions under ``belief`` (over states) for the goal key ``goal``: the
        moves', PRESS's (the belief on the goal), and each move and press's (the belief that the move
        ends on the goal)."""
        gamma = self.config.gamma
        moves = gamma * np.einsum("s,smt,t->m", belief, self._moves, self._values[goal])
        if self.config.optimism:
            seen = belief @ (self._visits >= 1.0)
            moves = np.where(seen >= 0.5, moves, gamma)
        values = np.append(moves, belief[self.state_class == goal].sum())
        if self.config.move_press:
            values = np.append(values, np.einsum("s,smt,t->m", belief, self._moves, self._rewards[goal]))
        return values

    def policy_action(
        self,
        observation: dict,
        step: int,
        explore: bool,
        rng: np.random.Generator,
        deterministic: bool = False,
    ) -> int | np.ndarray:
        """Epsilon-greedy on the QMDP values exploring, else with ``test_epsilon``; 0 if ``deterministic``.
        On a continuous task the chosen action as its :func:`continuous_actions` row; with ``locate``,
        a test episode's steps from where the map places the sensor (:meth:`located_action`)."""
        if self.locator is not None and not explore:
            located = self.located_action(observation)
            if located is not None:
                return located
        belief = self.belief(observation, stream=explore)
        state = int(belief.argmax())
        taken = self._taken_from(explore, state)
        epsilon = 0.0 if deterministic else (self.epsilon(step) if explore else self.config.test_epsilon)
        if rng.random() < epsilon:
            action = self._random_index(rng)
        else:
            goal = int(np.argmax(observation["desired_goal"]))
            values = self.action_values(belief, goal)
            action = int((values - self.config.repeat_penalty * taken).argmax())
            test_press = action == PRESS and not explore
            if test_press and (self._unread_goal(goal) or self._first_frame(observation)):
                belief, state, taken = self._restart(observation)  # from the frame, and no press
                values = self.action_values(belief, goal)
                values[PRESS] = -np.inf
                action = int((values - self.config.repeat_penalty * taken).argmax())
        self._taken[explore][state, action] += 1
        if not explore and action < PRESS and self.config.press_accept is not None:
            goal = self.state_class == int(np.argmax(observation["desired_goal"]))
            if belief @ self._moves[:, action, :] @ goal >= self.config.press_accept:
                return self._as_action(PRESS + 1 + action)  # the move, and a press at its end
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

    @torch.no_grad()
    def located_action(self, observation: dict[str, np.ndarray]) -> np.ndarray | None:
        """With ``locate``, a test step aimed by the map (:func:`~tactile_braille.agents.locator.
        locate_action`), or None where the key graph acts: until a frame is read as a key, and for the
        rest of an episode once a press the map aimed pressed nothing (the graph then starts again from
        the frame, as at an episode's start)."""
        previous = np.asarray(observation["previous_action"])
        if not previous.any():  # a new episode: the map acts once a frame is read as a key
            self._where[False] = None
        elif isinstance(self._where.get(False), np.ndarray) and previous[2] >= 1.0 - 1e-6:  # pressed nothing
            self._where[False] = False  # the graph for the rest of the episode, from this frame on
            self._beliefs[False] = None
            return None
        where = self._where.get(False)
        if where is False or float(self.locator.separation) < self.config.locate_ready:
            return None
        reading = self.read(observation["observation"][None])[0]
        key = int(reading.argmax())
        if key < self.keys and reading[key] >= self.config.locate_accept:
            frame = torch.as_tensor(np.moveaxis(observation["observation"], -1, 0)[None], device=self.device)
            self.locator.eval()
            where = self.locator(frame, torch.tensor([key], device=self.device))[0].double().cpu().numpy()
        if where is None:
            return None
        goal = int(np.argmax(observation["desired_goal"]))
        targets = self.locator.targets[goal].double().cpu().numpy()
        chosen = locate_action(where, targets, self.locator.safety[goal].double().cpu().numpy(),
                               self.config.locate_margin)  # fmt: skip
        if chosen is None:
            return None
        move, ends = chosen
        self._where[False] = where + move
        return np.array([*move, 1.0 if ends else self.config.sense_depth], dtype=np.float32)

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
        """The planner's action index (moves, then PRESS, then the moves and presses) of each of
        ``actions``: discrete indices (N,), one-hot previous actions (N, 5), or continuous ones (N, 3),
        which must be its own.

        Raises:
            ValueError: a continuous action that is none of :func:`continuous_actions` (a forced final
                press, a move with the deepest tap without ``move_press``: the planner learns only from
                its own actions).
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
        if self.locator is not None and len(self.pairs):
            index = rng.integers(len(self.pairs), size=min(batch_size, len(self.pairs)))
            frames = buffer.store.observations(self.pairs[index].ravel())
            batch.update(pair_first=frames[0::2], pair_second=frames[1::2], pair_keys=self.pair_keys[index],
                         pair_moves=self.pair_moves[index])  # fmt: skip
        return batch

    def update(self, batch: dict[str, np.ndarray]) -> dict[str, float]:
        """One gradient step of the reader's cross-entropy on labelled frames, and with ``locate`` one of
        the map's on its pairs (:func:`~tactile_braille.agents.locator.locator_loss`)."""
        if len(batch["classes"]) == 0:
            return {}
        t = self.tensors(batch)
        self.reader.train()
        with self.autocast():
            loss = F.cross_entropy(self.reader(t["frames"]).float(), t["classes"])
        self.optimiser.zero_grad(set_to_none=True)
        loss.backward()
        self.optimiser.step()
        metrics = {"losses/reader_loss": loss.item(), "charts/labelled_frames": float(len(self.label_frames))}
        if self.locator is not None:  # every epoch's row has the map's columns (NaN: no pairs yet)
            metrics.update(
                {"losses/locator_loss": float("nan"), "charts/located_pairs": float(len(self.pairs))}
            )
        if "pair_first" in t:  # the map's step on pairs of frames and the moves between them
            self.locator.train()
            with self.autocast():
                located = locator_loss(self.locator, t["pair_first"], t["pair_second"], t["pair_keys"],
                                       t["pair_moves"])  # fmt: skip
            self.locator_optimiser.zero_grad(set_to_none=True)
            located.backward()
            self.locator_optimiser.step()
            metrics["losses/locator_loss"] = located.item()
        return metrics

    def refit(self, buffer) -> None:
        """Refit the graph, the labels and the values from the replay's transitions."""
        transitions = replay_order(buffer)
        self.fitted_size, self.refits = buffer.size, self.refits + 1
        if len(transitions) == 0:
            return
        this, after = buffer.frame_index[transitions, 0], buffer.frame_index[transitions, 1]
        indices = self.action_indices(buffer.actions[transitions])
        actions = graph_moves_of(indices)  # a move and a press counted as its move
        achieved, dones = buffer.achieved[transitions].astype(np.int64), buffer.dones[transitions] > 0
        frames, rows = np.unique(np.concatenate([this, after]), return_inverse=True)
        row_this, row_after = rows[: len(this)], rows[len(this) :]
        probabilities = self.read(buffer.store.observations(frames)).astype(np.float64)
        reading = probabilities.copy()  # the reader's own, for the map (its labels are written over these)

        pressed, moved = presses(indices), indices > PRESS
        anchors = np.full(len(frames), -1)
        # A press labels the frame it was chosen on (it does not move), a move and a press the frame
        # it reached. A press of no goal key shows nothing: on the discrete tasks it goes on (a cell off
        # the keys), on the continuous ones it may also end the episode (a key outside the task's).
        pressed_on = np.where(moved, row_after, row_this)
        anchors[pressed_on[pressed]] = np.where(achieved[pressed] >= 0, achieved[pressed], self.keys)
        known = anchors >= 0
        prior = np.bincount(anchors[known], minlength=self.classes) + 1.0
        prior /= prior.sum()
        evidence = None
        if self.config.backtrack_evidence > 0:  # each frame's own reading over the prior, floored
            evidence = ((probabilities + 1e-3) / prior) ** self.config.backtrack_evidence
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
            moves = graph_moves(counts, off_keys, self.config.graph_prior, self.config.backoff, self.shifts)
            occupancy = states_this.sum(0) + 1e-3 if self.config.backtrack_prior else None
            labels = backtrack(moves, self.state_class, anchors, row_this, actions, achieved, starts, ends,
                               self.config.sharpen, self.config.accept, moved, evidence,
                               occupancy)  # fmt: skip
        self.graph.moves.copy_(torch.as_tensor(moves))
        visits = counts.sum(-1)
        visits[off_keys:] = visits[off_keys:].sum(0)  # a state off the keys borrows the others' moves
        self.graph.visits.copy_(torch.as_tensor(visits))
        self.graph.prior.copy_(torch.as_tensor(prior))
        labelled = np.flatnonzero(labels >= 0)
        self.label_frames, self.label_classes = frames[labelled], labels[labelled]
        if self.locator is not None:
            read = np.where(reading.max(-1) >= self.config.locate_accept, reading.argmax(-1), -1)
            known = np.where(labels >= 0, labels, read)  # a label, else what the reader reads surely
            known[row_after[pressed]] = -1  # a press's frame is a deep tap: the map reads light ones
            self._pair(buffer, frames, np.stack([row_this, row_after], 1), known, indices, firsts, pressed,
                       achieved)  # fmt: skip
        self._plan()

    def _pair(self, buffer, frames, rows, labels, indices, firsts, pressed, achieved) -> None:
        """The map's pairs of frames (:func:`~tactile_braille.agents.locator.frame_pairs`) from each
        frame's class (``labels``: the refit's label, else what the reader reads with ``locate_accept``,
        else -1), and its presses, for the targets :meth:`end_epoch` places."""
        keys = np.where(labels < self.keys, labels, -1)
        deltas = self.continuous[indices, :2].astype(np.float64)
        first, second, moves = frame_pairs(rows, keys, deltas, firsts, self.config.locate_span)
        self.pairs = np.stack([frames[first], frames[second]], 1)
        self.pair_keys, self.pair_moves = np.stack([keys[first], keys[second]], 1), moves
        outcomes = np.where((achieved >= 0) & (achieved < self.keys), achieved, -1)
        self._press_data = (buffer, frames, rows, keys, deltas, firsts, pressed, outcomes)

    @torch.no_grad()
    def end_epoch(self) -> None:
        """With ``locate``, the map's targets from the last refit's presses
        (:func:`~tactile_braille.agents.locator.press_points`, :func:`~tactile_braille.agents.locator.
        key_targets`), placed by the map as it now is."""
        if self.locator is None or self._press_data is None:
            return
        buffer, frames, rows, keys, deltas, firsts, pressed, outcomes = self._press_data
        located = keys >= 0
        positions = np.zeros((len(frames), 2))
        self.locator.eval()
        slots = np.flatnonzero(located)
        for i in range(0, len(slots), 512):
            chunk = slots[i : i + 512]
            images = torch.as_tensor(buffer.store.observations(frames[chunk]), device=self.device)
            key = torch.as_tensor(keys[chunk], device=self.device)
            positions[chunk] = self.locator(images, key).double().cpu().numpy()
        points, kinds = press_points(positions, located, rows, deltas, firsts, pressed, outcomes)
        targets, safety = key_targets(points, kinds, self.keys)
        self.locator.targets.copy_(torch.as_tensor(targets))
        self.locator.safety.copy_(torch.as_tensor(safety))
        self.locator.separation.fill_(press_separation(points, kinds))

    def _plan(self) -> None:
        """Value iteration per goal on the graph: ``values[g, s]``, pressing worth 1 on the goal key."""
        self._moves = self.graph.moves.double().cpu().numpy()
        self._visits = self.graph.visits.double().cpu().numpy()
        self._prior = self.graph.prior.double().cpu().numpy()
        rewards = (np.arange(self.keys)[:, None] == self.state_class[None]).astype(np.float64)
        self._rewards = rewards
        if self.config.move_press:  # a move and a press: the goal reached and pressed in this step
            rewards = np.maximum(rewards, np.einsum("smt,gt->gsm", self._moves, rewards).max(-1))
        values = rewards.copy()
        lost = self.config.lost_value
        for _ in range(self.config.planning_sweeps):
            ahead = values
            if lost is not None:  # the generic nothing, entered from elsewhere
                ahead = values.copy()
                ahead[:, self.lost_states] *= lost
            backed = self.config.gamma * np.einsum("smt,gt->gsm", self._moves, ahead).max(-1)
            if lost is not None:  # acting from it, its own moves as they are
                backed[:, self.lost_states] = self.config.gamma * np.einsum(
                    "smt,gt->gsm", self._moves[self.lost_states], values
                ).max(-1)
            values = np.maximum(rewards, backed)
        self._values = values

    def load_state_dict(self, state: dict) -> None:
        super().load_state_dict(state)
        self.fitted_size = -1  # the labels are the replay's: read again at the next update
        self._plan()

    def load_policy_state_dict(self, state: dict) -> None:
        super().load_policy_state_dict(state)
        self._plan()


def graph_moves(
    counts: np.ndarray, keys: int, prior: float, backoff: float, shifts: np.ndarray | None = None
) -> np.ndarray:
    """``P(state' | state, move)`` from soft counts (states, moves, states): a key state's with
    ``prior`` pseudo-counts spread evenly; a state off the keys' with ``backoff`` pseudo-counts spread as
    the moves of all states off the keys together (it is seen more rarely than any key). With
    ``shifts`` (dead reckoning, :func:`reckon_shifts`) those pooled moves are a translation: the keys
    they reach as they are, and all they stay off the keys at the state the move shifts to."""
    moves = counts + prior / counts.shape[-1]
    pooled = counts[keys:].sum(0) + prior / counts.shape[-1]
    pooled /= pooled.sum(-1, keepdims=True)
    if shifts is None:
        moves[keys:] = counts[keys:] + backoff * pooled
    else:
        backed = np.zeros_like(counts[keys:])
        backed[:, :, :keys] = pooled[None, :, :keys]
        off_states = np.arange(len(backed))[:, None]
        backed[off_states, np.arange(MOVES)[None], shifts[keys:]] += pooled[:, keys:].sum(-1)[None]
        moves[keys:] = counts[keys:] + backoff * backed
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
    moved: np.ndarray | None = None,
    evidence: np.ndarray | None = None,
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
        moved: which transitions' presses also moved (a move and a press, whose ``actions`` is its
            move): the pressed key is where it led, and its own first frame is read back too (None: no
            press moved).
        evidence: each frame's likelihood of each class (frames, classes), weighed into the belief
            of the frame it reaches going back (a backward Bayes filter); None: the graph alone.
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
        last = end if moved is not None and moved[end] else end - 1
        for step in range(last, start - 1, -1):
            if actions[step] != PRESS:  # a press on nothing stays where it was
                belief = sharp[:, actions[step], :] @ belief
            if evidence is not None:
                belief = belief * evidence[rows[step]][state_class]
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
