"""The agents (agents/dqn.py, sac.py, sac_discrete.py, td3.py, common.py): the actor's encoder, TD3's delay,
checkpoints and policy snapshots, spaces and precision, bf16, the temperature, asymmetric critics.

Small and fast: tiny dense layers (the paper's encoder is kept), batches of a
few transitions, one torch thread. The spaces and observations come from the
real tasks on the small test datasets; the asymmetric critics learn from
feature observations whose reward only the sensor pose explains
(tests/feature_agents.py).
"""

from __future__ import annotations

import math
import types
import warnings

import gymnasium as gym
import numpy as np
import pytest
import torch
from torch import nn
from torch.nn import functional as F

from agents_helpers import ALGOS, CONTINUOUS_TASK, DISCRETE_TASK, HIDDEN, same_weights, through_file
from feature_agents import ACTIONS, FEATURES, GOALS, PREVIOUS, batch, make
from tactile_braille.agents import common
from tactile_braille.agents.common import POSE_SIZE
from tactile_braille.agents.registry import agent_spec

ACTOR_CRITICS = ("sac_discrete", "sac", "td3")


pytestmark = pytest.mark.usefixtures("one_torch_thread")


# ---------------------------------------------------------------- agents on the tasks' spaces
@pytest.fixture(scope="module")
def tasks(env_datasets) -> dict[str, dict]:
    """Spaces and a few real observations of a discrete and a continuous task."""
    tasks = {}
    for kind, env_id in (("discrete", DISCRETE_TASK), ("continuous", CONTINUOUS_TASK)):
        env = gym.make(env_id, dataset=env_datasets[env_id])
        observations = []
        for seed in range(3):
            observation, _ = env.reset(seed=seed)
            observations.append(observation)
            env.action_space.seed(seed)
            observation, *_ = env.step(env.action_space.sample())
            observations.append(observation)
        tasks[kind] = {
            "observation_space": env.observation_space,
            "action_space": env.action_space,
            "observations": observations,
        }
        env.close()
    return tasks


def build(algo: str, tasks: dict, seed: int = 0, precision: str = "fp32", **hyperparameters):
    """An agent for ``algo`` with tiny dense layers, its weights drawn from torch seed ``seed``."""
    agent_class, config_class, kind = ALGOS[algo]
    torch.manual_seed(seed)
    config = config_class(**{"hidden": HIDDEN, **hyperparameters})
    task = tasks[kind]
    return agent_class(
        task["observation_space"], task["action_space"], config, device="cpu", precision=precision
    )


def make_batch(algo: str, tasks: dict, size: int = 8, seed: int = 0) -> dict[str, np.ndarray]:
    """A replay batch by hand: binary images, one-hot goals, valid actions, some rewards and ends."""
    task = tasks[ALGOS[algo][2]]
    rng = np.random.default_rng(seed)
    goals = task["observation_space"]["desired_goal"].shape[0]
    previous = task["observation_space"]["previous_action"].shape[0]
    action_space = task["action_space"]
    if isinstance(action_space, gym.spaces.Discrete):
        actions = rng.integers(action_space.n, size=size)
    else:
        actions = rng.uniform(-1, 1, (size, *action_space.shape)).astype(np.float32)

    def images():
        return ((rng.random((size, 1, 100, 100)) < 0.3) * 255).astype(np.uint8)

    return {
        "images": images(),
        "previous_actions": rng.random((size, previous)).astype(np.float32),
        "goals": np.eye(goals, dtype=np.float32)[rng.integers(goals, size=size)],
        "actions": actions,
        "rewards": (rng.random(size) < 0.4).astype(np.float32),
        "next_images": images(),
        "next_previous_actions": rng.random((size, previous)).astype(np.float32),
        "dones": (rng.random(size) < 0.3).astype(np.float32),
    }


def state_inputs(agent, batch) -> tuple[torch.Tensor, ...]:
    t = agent.tensors(batch)
    return t["images"], t["goals"], t["previous_actions"]


def snapshot(module: nn.Module) -> dict[str, torch.Tensor]:
    return {name: value.detach().clone() for name, value in module.state_dict().items()}


def same_tensors(a: dict[str, torch.Tensor], b: dict[str, torch.Tensor]) -> bool:
    return a.keys() == b.keys() and all(torch.equal(a[name], b[name]) for name in a)


# ---------------------------------------------------------------- the actor's encoder
def actor_outputs_sum(actor, inputs) -> torch.Tensor:
    outputs = actor(*inputs)
    outputs = outputs if isinstance(outputs, tuple) else (outputs,)
    return sum((o.float() * torch.linspace(0.5, 1.5, o.numel()).view_as(o)).sum() for o in outputs)


@pytest.mark.parametrize("algo", ACTOR_CRITICS)
def test_the_actor_has_its_own_encoder(algo, tasks):
    agent = build(algo, tasks)
    own = agent.actor.trunk.encoder
    assert own is not agent.critics[0].trunk.encoder
    assert {id(p) for p in own.parameters()} <= {id(p) for p in agent.actor.parameters()}
    assert "trunk.encoder.layers.0.weight" in agent.actor.state_dict()
    actor_outputs_sum(agent.actor, state_inputs(agent, make_batch(algo, tasks))).backward()
    assert own.layers[0].weight.grad is not None and own.layers[0].weight.grad.abs().sum() > 0
    assert all(p.grad is None for p in agent.critics[0].trunk.encoder.parameters())


# ---------------------------------------------------------------- TD3's delay
def test_td3_updates_the_actor_every_second_critic_update_and_checkpoints_the_counter(tasks):
    agent = build("td3", tasks, policy_delay=2)
    batch = make_batch("td3", tasks)
    actor, actor_target, critic_targets = (
        snapshot(agent.actor),
        snapshot(agent.actor_target),
        snapshot(agent.critic_targets),
    )
    critics = snapshot(agent.critics)

    first = agent.update(batch)
    assert int(agent.critic_updates) == 1
    assert "losses/actor_loss" not in first
    assert not same_tensors(critics, snapshot(agent.critics))
    assert same_tensors(actor, snapshot(agent.actor))
    assert same_tensors(actor_target, snapshot(agent.actor_target))
    assert same_tensors(critic_targets, snapshot(agent.critic_targets))
    state = through_file(agent.state_dict())  # saved between the two updates: the counter is 1

    second = agent.update(batch)
    assert int(agent.critic_updates) == 2
    assert math.isfinite(second["losses/actor_loss"])
    assert not same_tensors(actor, snapshot(agent.actor))
    assert not same_tensors(actor_target, snapshot(agent.actor_target))
    assert not same_tensors(critic_targets, snapshot(agent.critic_targets))

    fresh = build("td3", tasks, seed=1, policy_delay=2)
    fresh.load_state_dict(state)
    assert int(fresh.critic_updates) == 1
    loaded_actor = snapshot(fresh.actor)
    assert "losses/actor_loss" in fresh.update(batch)  # its next update is the second: the actor's
    assert not same_tensors(loaded_actor, snapshot(fresh.actor))


# ---------------------------------------------------------------- checkpoints and policy snapshots
@pytest.mark.parametrize("algo", list(ALGOS))
def test_checkpoint_round_trip_gives_the_same_actions_and_updates(algo, tasks):
    agent = build(algo, tasks, seed=0)
    batch = make_batch(algo, tasks, seed=0)
    for step in range(2):
        agent.update(make_batch(algo, tasks, seed=10 + step))
    fresh = build(algo, tasks, seed=99)
    observations = tasks[ALGOS[algo][2]]["observations"]

    def actions(which):
        return [np.asarray(which.policy_action(o, 0, False, np.random.default_rng(0))) for o in observations]

    fresh.load_state_dict(through_file(agent.state_dict()))
    for mine, theirs in zip(actions(agent), actions(fresh), strict=True):
        np.testing.assert_array_equal(mine, theirs)
    for name in agent.checkpointed:
        part = getattr(agent, name)
        if isinstance(part, nn.Module):
            assert same_tensors(snapshot(part), snapshot(getattr(fresh, name))), name

    torch.manual_seed(5)
    expected = agent.update(batch)
    torch.manual_seed(5)
    got = fresh.update(batch)
    assert got == expected
    for name in agent.checkpointed:
        part = getattr(agent, name)
        if isinstance(part, nn.Module):
            assert same_tensors(snapshot(part), snapshot(getattr(fresh, name))), name

    # An agent that did not load the checkpoint updates differently (the comparison can fail).
    other = build(algo, tasks, seed=99)
    torch.manual_seed(5)
    assert other.update(batch) != expected


@pytest.mark.parametrize("algo", list(ALGOS))
def test_load_state_dict_names_a_missing_part(algo, tasks):
    agent = build(algo, tasks)
    state = agent.state_dict()
    assert set(state) == set(agent.checkpointed)
    missing = agent.checkpointed[1]
    del state[missing]
    with pytest.raises(ValueError, match=missing):
        build(algo, tasks).load_state_dict(state)


@pytest.mark.parametrize("algo", ["dqn", "sac"])
def test_policy_snapshots_act_like_the_agent(algo, env_datasets):
    task = CONTINUOUS_TASK if algo == "sac" else "tactile_braille/DiscreteArrows-v0"
    env = gym.make(task, dataset=env_datasets[task])
    config = agent_spec(algo).config(hidden=(32,))
    agent = agent_spec(algo).agent_class(env.observation_space, env.action_space, config)
    fresh = agent_spec(algo).agent_class(env.observation_space, env.action_space, config)
    snapshot = agent.policy_state_dict()
    assert set(snapshot) == set(type(agent).policy_parts)  # no optimisers, no targets
    fresh.load_policy_state_dict(snapshot)
    observation, _ = env.reset(seed=4)
    rng = np.random.default_rng(0)
    np.testing.assert_array_equal(
        agent.policy_action(observation, 0, explore=False, rng=rng),
        fresh.policy_action(observation, 0, explore=False, rng=rng),
    )
    with pytest.raises(ValueError, match="policy snapshot lacks"):
        fresh.load_policy_state_dict({})


# ---------------------------------------------------------------- spaces and precision
@pytest.mark.parametrize(
    ("algo", "action_space", "message"),
    [
        ("dqn", gym.spaces.Box(-1, 1, (3,), np.float32), "Discrete"),
        ("sac_discrete", gym.spaces.Box(-1, 1, (3,), np.float32), "Discrete"),
        ("sac", gym.spaces.Discrete(5), r"Box\(-1, 1\)"),
        ("td3", gym.spaces.Discrete(5), r"Box\(-1, 1\)"),
        ("sac", gym.spaces.Box(-2, 2, (3,), np.float32), r"Box\(-1, 1\)"),
        ("td3", gym.spaces.Box(-2, 2, (3,), np.float32), r"Box\(-1, 1\)"),
        ("sac", gym.spaces.Box(-1, 1, (3, 2), np.float32), r"flat Box"),
    ],
)
def test_wrong_action_spaces_are_refused(algo, action_space, message, tasks):
    agent_class, config_class, kind = ALGOS[algo]
    with pytest.raises(ValueError, match=message):
        agent_class(tasks[kind]["observation_space"], action_space, config_class(hidden=HIDDEN))


@pytest.mark.parametrize("algo", list(ALGOS))
def test_unknown_precision_and_plain_observations_are_refused(algo, tasks):
    with pytest.raises(ValueError, match="precision"):
        build(algo, tasks, precision="fp16")
    agent_class, config_class, kind = ALGOS[algo]
    plain = gym.spaces.Box(0, 255, (100, 100, 1), np.uint8)
    with pytest.raises(ValueError, match="goal-conditioned"):
        agent_class(plain, tasks[kind]["action_space"], config_class(hidden=HIDDEN))


# ---------------------------------------------------------------- bf16
BF16_TOLERANCE = 0.02
"""Largest bf16-vs-fp32 deviation of Q-values, as a share of max |Q|. bfloat16 keeps 8 bits of
mantissa (relative step 0.4 %); measured deviations after a few updates are 0.2-0.7 %."""


@pytest.mark.parametrize("algo", ["dqn", "sac"])
def test_bf16_autocast_stays_close_to_fp32(algo, tasks):
    full = build(algo, tasks, seed=0, hidden=(64,))
    for step in range(3):  # Q-values away from their near-zero start
        full.update(make_batch(algo, tasks, size=32, seed=20 + step))
    half = build(algo, tasks, seed=1, precision="bf16", hidden=(64,))
    half.load_state_dict(through_file(full.state_dict()))
    batch = make_batch(algo, tasks, size=32, seed=3)
    t = full.tensors(batch)
    inputs = (t["images"], t["goals"], t["previous_actions"])

    def q_values(agent):
        with torch.no_grad(), agent.autocast():
            if algo == "dqn":
                return agent.q(*inputs).float()
            return agent.critics[0](*inputs, t["actions"]).float()

    q_full, q_half = q_values(full), q_values(half)
    scale = q_full.abs().max()
    assert scale > 0.1
    assert not torch.equal(q_full, q_half)  # bf16 autocast is really on
    assert (q_full - q_half).abs().max() < BF16_TOLERANCE * scale

    torch.manual_seed(7)
    losses_full = full.update(batch)
    torch.manual_seed(7)
    losses_half = half.update(batch)
    loss = "losses/q_loss" if algo == "dqn" else "losses/qf_loss"
    assert losses_half[loss] == pytest.approx(losses_full[loss], rel=0.03)
    if algo == "sac":
        assert losses_half["losses/actor_loss"] == pytest.approx(losses_full["losses/actor_loss"], rel=0.03)


@pytest.mark.parametrize("native", [True, False])
def test_bf16_warns_where_the_processor_only_emulates_it(native, tasks, monkeypatch):
    monkeypatch.setattr(common, "native_bf16", lambda device: native)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        build("dqn", tasks, precision="bf16")
        build("dqn", tasks, precision="fp32")
    emulated = [w for w in caught if issubclass(w.category, RuntimeWarning) and "emulated" in str(w.message)]
    assert len(emulated) == (0 if native else 1)  # bf16 alone, and only where it is emulated
    if not native:
        assert "--precision fp32" in str(emulated[0].message)


def test_native_bf16_reads_the_processor_flags_without_onednn_s_check(monkeypatch):
    monkeypatch.setattr(torch.ops, "mkldnn", types.SimpleNamespace())  # a torch without the check
    monkeypatch.setattr(common, "_cpu_flags", lambda: frozenset({"avx2", "fma"}))
    assert common.native_bf16("cpu") is False
    monkeypatch.setattr(common, "_cpu_flags", lambda: frozenset({"avx2", "avx512_bf16"}))
    assert common.native_bf16("cpu") is True
    monkeypatch.setattr(common, "_cpu_flags", lambda: frozenset({"amx_bf16"}))
    assert common.native_bf16(torch.device("cpu")) is True


# ---------------------------------------------------------------- SAC's temperature
@pytest.mark.parametrize("algo", ["sac", "sac_discrete"])
def test_initial_temperature_is_a_hyperparameter(algo, env_datasets):
    from tactile_braille.agents.presets import preset_config

    task = "tactile_braille/ContinuousArrows-v0" if algo == "sac" else "tactile_braille/DiscreteArrows-v0"
    env = gym.make(task, dataset=env_datasets[task])
    algorithm = agent_spec(algo)
    agent = algorithm.agent_class(
        env.observation_space, env.action_space, algorithm.config(initial_alpha=0.05)
    )
    assert float(agent.log_alpha.detach().exp()) == pytest.approx(0.05)
    assert (
        float(algorithm.agent_class(env.observation_space, env.action_space).log_alpha.detach().exp()) == 1.0
    )  # paper
    with pytest.raises(ValueError, match="initial_alpha must be positive"):
        algorithm.config(initial_alpha=0.0)
    assert preset_config("fast", task, algo).agent.initial_alpha == 0.05


# ---------------------------------------------------------------- asymmetric critics
def critic_error(agent, data: dict[str, np.ndarray]) -> float:
    t = agent.tensors(data)
    with torch.no_grad():
        poses = (t["poses"],) if agent.config.critic_pose else ()
        q = agent.critics[0](t["images"], t["goals"], t["previous_actions"], t["actions"], *poses)
    return float(((q - t["rewards"]) ** 2).mean())


@pytest.mark.parametrize("algo", ["sac", "td3"])
def test_only_the_critics_see_the_pose(algo):
    agent, plain = make(algo, True), make(algo, False)
    first_layer = [critic.trunk.dense[0].in_features for critic in agent.critics]
    assert first_layer == [plain.critics[0].trunk.dense[0].in_features + POSE_SIZE] * 2
    assert agent.actor.trunk.dense[0].in_features == plain.actor.trunk.dense[0].in_features
    observation = {
        "observation": np.zeros(FEATURES, np.float32),
        "previous_action": np.zeros(PREVIOUS, np.float32),
        "desired_goal": np.eye(GOALS, dtype=np.float32)[0],
    }
    action = agent.policy_action(observation, 0, explore=False, rng=np.random.default_rng(0))
    assert action.shape == (ACTIONS,)  # acting needs no pose


@pytest.mark.parametrize("algo", ["sac", "td3"])
def test_an_asymmetric_update_without_poses_says_what_is_missing(algo):
    agent = make(algo, True)
    with pytest.raises(ValueError, match="'poses' and 'next_poses'"):
        agent.update(batch(np.random.default_rng(0), poses=False))


@pytest.mark.parametrize("algo", ["sac", "td3"])
def test_the_asymmetric_critic_learns_a_value_that_only_the_pose_explains(algo):
    """The reward depends on the pose, hidden from the observation: only the pose-aware critic fits it."""
    rng = np.random.default_rng(0)
    agents = {pose: make(algo, pose, seed=1) for pose in (True, False)}
    for _ in range(400):
        data = batch(rng)
        for agent in agents.values():
            agent.update(data)
    held_out = batch(np.random.default_rng(99), size=2000)
    with_pose, without = critic_error(agents[True], held_out), critic_error(agents[False], held_out)
    # A critic blind to the pose can do no better than the reward's variance given the action
    # (about 0.17 for this reward); the pose-aware one approaches the noise-free target.
    assert without > 0.12, without
    assert with_pose < 0.5 * without, (with_pose, without)


@pytest.mark.parametrize("algo", ["sac", "td3"])
def test_targets_see_the_next_poses_and_the_critics_and_the_actors_loss_the_poses(algo):
    agent = make(algo, True, policy_delay=1) if algo == "td3" else make(algo, True)
    targets = agent.critic_targets if algo == "td3" else agent.targets
    seen: dict[str, list[torch.Tensor]] = {"online": [], "target": []}

    def hook(kind):
        return lambda module, inputs: seen[kind].append(inputs[-1].detach().clone())

    for critic in agent.critics:
        critic.register_forward_pre_hook(hook("online"))
    for target in targets:
        target.register_forward_pre_hook(hook("target"))
    data = batch(np.random.default_rng(0))
    data["dones"] = np.zeros_like(data["dones"])  # the targets' values count
    agent.update(data)
    poses, next_poses = torch.as_tensor(data["poses"]), torch.as_tensor(data["next_poses"])
    assert seen["target"] and all(torch.equal(p, next_poses) for p in seen["target"])
    # Both critics' losses and the actor's loss (the first critic, or both for SAC's minimum).
    assert len(seen["online"]) >= 3 and all(torch.equal(p, poses) for p in seen["online"])


# ---------------------------------------------------------------- the released code's DQN
def _blend(old: dict, new: dict, tau: float) -> dict:
    return {name: (1 - tau) * old[name] + tau * new[name] for name in old}


def _close(a: dict, b: dict) -> bool:
    return all(torch.allclose(a[name], b[name], atol=1e-6) for name in a)


@pytest.mark.parametrize("schedule", ["update", "epoch"])
def test_the_dqn_target_moves_per_update_as_the_paper_or_once_per_epoch_as_the_release(tasks, schedule):
    tau = 0.005 if schedule == "update" else 0.995
    agent = build("dqn", tasks, target_update=schedule, tau=tau)
    before = snapshot(agent.target)
    for seed in range(3):
        agent.update(make_batch("dqn", tasks, seed=seed))
        online = snapshot(agent.q)
        if schedule == "update":  # one Polyak step of tau after each update
            assert _close(snapshot(agent.target), _blend(before, online, tau))
            before = snapshot(agent.target)
        else:  # the target stays put through the epoch's updates
            assert same_tensors(snapshot(agent.target), before)
    moved = snapshot(agent.target)
    agent.end_epoch()
    if schedule == "update":
        assert same_tensors(snapshot(agent.target), moved)
    else:  # then moves 99.5 % of the way to the online network (the release's `polyak: 0.005`)
        assert _close(snapshot(agent.target), _blend(before, snapshot(agent.q), 0.995))


def test_the_dqn_loss_is_half_the_squared_error_or_huber(tasks):
    batch = make_batch("dqn", tasks)
    losses = {}
    for loss in ("mse", "huber"):
        agent = build("dqn", tasks, loss=loss)
        t = agent.tensors(batch)
        with torch.no_grad():
            next_q = agent.q(t["next_images"], t["goals"], t["next_previous_actions"])
            chosen = agent.target(t["next_images"], t["goals"], t["next_previous_actions"]).gather(
                -1, next_q.argmax(-1, keepdim=True)
            )
            target = t["rewards"] + 0.95 * (1 - t["dones"]) * chosen.squeeze(-1)
            q = agent.q(*state_inputs(agent, batch)).gather(-1, t["actions"][:, None]).squeeze(-1)
        error = q - target
        huber = torch.where(error.abs() < 1, 0.5 * error**2, error.abs() - 0.5).mean()
        losses[loss] = (
            agent.update(batch)["losses/q_loss"],
            (0.5 * error**2).mean() if loss == "mse" else huber,
        )
    for computed, expected in losses.values():
        assert computed == pytest.approx(float(expected), rel=1e-5)


@pytest.mark.parametrize("algo", list(ALGOS))
def test_every_optimiser_takes_the_configured_adam_epsilon(tasks, algo):
    agent = build(algo, tasks, adam_eps=1e-4)
    optimisers = [value for value in vars(agent).values() if isinstance(value, torch.optim.Optimizer)]
    assert optimisers and all(group["eps"] == 1e-4 for o in optimisers for group in o.param_groups)


def test_exploration_steps_down_once_per_epoch_with_a_schedule_interval(tasks):
    stepwise, staircase = build("dqn", tasks), build("dqn", tasks, schedule_interval=250)
    assert stepwise.epsilon(100) == pytest.approx(1.0 - 0.9 * 100 / 2000)
    assert [staircase.epsilon(s) for s in (0, 249, 250, 499, 500)] == pytest.approx(
        [1.0, 1.0, 0.8875, 0.8875, 0.775]
    )  # the released log's "Actor Noise": 0.8875, 0.775, ...
    assert staircase.epsilon(10_000) == pytest.approx(0.1)
    td3 = build("td3", tasks, schedule_interval=250, noise_start=1.0, noise_end=0.05)
    assert [td3.noise(s) for s in (249, 250)] == pytest.approx([1.0, 1.0 - 0.95 * 250 / 2000])


# ---------------------------------------------------------------- n-step returns
@pytest.mark.parametrize("algo", list(ALGOS))
def test_a_batch_of_n_step_returns_discounts_its_bootstrap_by_gamma_to_the_steps(tasks, algo):
    data = make_batch(algo, tasks)
    data["dones"] = np.zeros_like(data["dones"])  # the bootstrapped values count
    steps = {**data, "steps": np.full(len(data["rewards"]), 2.0, dtype=np.float32)}
    torch.manual_seed(1)
    two_steps = build(algo, tasks, gamma=0.9)
    losses = two_steps.update(steps)
    torch.manual_seed(1)
    squared = build(algo, tasks, gamma=0.81)  # one step with gamma ** 2: the same targets
    expected = squared.update(data)
    assert losses == pytest.approx(expected, rel=1e-4)
    learnt = [agent.q if algo == "dqn" else agent.critics for agent in (two_steps, squared)]
    parameters, reference = (dict(module.named_parameters()) for module in learnt)
    assert all(torch.allclose(parameters[name], reference[name], atol=1e-6) for name in parameters)
    torch.manual_seed(1)
    plain = build(algo, tasks, gamma=0.9).update(data)
    assert plain != pytest.approx(losses, rel=1e-4)  # the steps changed the targets


# ---------------------------------------------------------------- every goal at once
@pytest.mark.parametrize("goal_heads", [False, True])
@pytest.mark.parametrize("algo", ["dqn", "sac_discrete"])
def test_every_goals_values_hold_each_goals_own(tasks, algo, goal_heads):
    """DQN's Q-network and discrete SAC's policy give every goal's outputs at once, each the
    output under that goal alone."""
    agent = build(algo, tasks, goal_heads=goal_heads)
    network = agent.q if algo == "dqn" else agent.actor

    def first(output):  # the policy's probabilities (beside their logs), or the Q-values
        return output[0] if isinstance(output, tuple) else output

    images, goals, previous = state_inputs(agent, make_batch(algo, tasks))
    with torch.no_grad():
        every = first(network.every_goal(images, previous))
        assert every.shape == (len(goals), goals.shape[1], agent.num_actions)
        for some in (goals, torch.roll(goals, 1, dims=-1)):
            rows = every[torch.arange(len(goals)), some.argmax(-1)]
            assert torch.allclose(first(network(images, some, previous)), rows, atol=1e-6)
    assert network.trunk.dense[0].in_features == 5184 + previous.shape[1] + (
        0 if goal_heads else goals.shape[1]
    )


def test_dqn_builds_the_released_codes_dueling_network_where_asked(tasks):
    agent = build("dqn", tasks, dueling_split=True, weights_init="released")
    assert agent.q.split == agent.target.split == HIDDEN[-1] // 2
    assert torch.all(agent.q.value.bias == 0) and agent.q.value.weight.std() > 0.1  # not near zero
    assert build("dqn", tasks).q.split == 0
    losses = agent.update(make_batch("dqn", tasks))
    assert np.isfinite(losses["losses/q_loss"])


def test_discrete_sac_builds_the_released_codes_plain_critics_and_initial_weights_where_asked(tasks):
    agent = build("sac_discrete", tasks, dueling=False, weights_init="released")
    for critic in (*agent.critics, *agent.targets):
        assert critic.value is None
    assert torch.all(agent.critics[0].advantage.bias == 0) and agent.critics[0].advantage.weight.std() > 0.1
    assert agent.actor.logits.weight.std() > 0.1  # not near zero, as ours
    assert build("sac_discrete", tasks).critics[0].value is not None  # dueling critics by default
    losses = agent.update(make_batch("sac_discrete", tasks))
    assert all(np.isfinite(value) for value in losses.values())


@pytest.mark.parametrize("algo", ["sac", "td3"])
def test_continuous_agents_build_the_released_codes_networks_where_asked(algo, tasks):
    """The released SAC's and TD3's networks: their initial weights, actions read in mm, and SAC's
    log deviation through a tanh; every network of the agent (targets too) takes them."""
    extra = {"log_std": "tanh"} if algo == "sac" else {}
    agent = build(algo, tasks, weights_init="released", action_input_scale=10.0, **extra)
    targets = agent.targets if algo == "sac" else [*agent.critic_targets, agent.actor_target]
    for network in (*agent.critics, agent.actor, *targets):
        assert network.action_scale == 10.0
    assert torch.all(agent.critics[0].q.bias == 0) and agent.critics[0].q.weight.std() > 0.05  # Glorot
    if algo == "sac":
        assert agent.actor.log_std_rule == "tanh" and build(algo, tasks).actor.log_std_rule == "clamp"
    assert build(algo, tasks).critics[0].action_scale == 1.0  # ours: actions in [-1, 1]
    losses = agent.update(make_batch(algo, tasks))
    assert all(np.isfinite(value) for value in losses.values())


def test_a_pressed_key_loss_trains_the_q_networks_encoder_to_name_the_pressed_key(tasks):
    """The key head reads the frames presses were made from; its loss is the cross-entropy of that reading
    against the pressed keys, reaches the encoder and leaves the TD loss alone; without press frames
    yet it adds nothing, and batches without them are refused."""
    data = make_batch("dqn", tasks)
    goals = tasks["discrete"]["observation_space"]["desired_goal"].shape[0]
    presses = {**data, "press_images": data["images"][:5], "press_keys": np.arange(5) % goals}
    plain, helped = build("dqn", tasks), build("dqn", tasks, pressed_key=0.5)
    assert same_weights(plain.q, helped.q)  # the head is made after the Q-network: the same start
    with torch.no_grad():
        t = helped.tensors(presses)
        expected = F.cross_entropy(helped.key_head(helped.q.trunk.encode(t["press_images"])), t["press_keys"])
    losses, plain_losses = helped.update(presses), plain.update(data)
    assert losses["losses/pressed_key_loss"] == pytest.approx(expected.item(), rel=1e-5)
    assert losses["losses/q_loss"] == pytest.approx(plain_losses["losses/q_loss"], rel=1e-6)
    assert not same_weights(helped.q.trunk.encoder, plain.q.trunk.encoder)  # its gradient reached it
    assert "key_head" in helped.state_dict() and "key_head" not in plain.state_dict()
    none_yet = {**data, "press_images": data["images"][:0], "press_keys": np.zeros(0, dtype=np.int64)}
    assert "losses/pressed_key_loss" not in build("dqn", tasks, pressed_key=0.5).update(none_yet)
    with pytest.raises(ValueError, match="PressFrames extra"):
        build("dqn", tasks, pressed_key=0.5).update(data)
    with pytest.raises(ValueError, match=r"pressed_key is a loss weight: at least 0, got -1\.0"):
        build("dqn", tasks, pressed_key=-1.0)


def test_unit_features_keep_the_q_networks_image_features_at_unit_length(tasks):
    """``unit_features``: the trunk's image features (what the key head and the dense layers read) have
    length 1 whatever the encoder's scale, in the online and the target network; by default they do not."""
    agent, plain = build("dqn", tasks, unit_features=True, pressed_key=0.5), build("dqn", tasks)
    images = torch.as_tensor(make_batch("dqn", tasks)["images"])
    with torch.no_grad():
        for parameter in agent.q.trunk.encoder.parameters():
            parameter.mul_(3.0)  # an encoder grown by an auxiliary loss
        for network in (agent.q, agent.target):
            lengths = network.trunk.encode(images).norm(dim=-1)
            assert torch.allclose(lengths, torch.ones_like(lengths), atol=1e-5)
        assert not torch.allclose(plain.q.trunk.encode(images).norm(dim=-1), torch.ones(len(images)))


def test_a_return_bound_lifts_each_target_to_at_least_its_episodes_return(tasks):
    """With ``return_bound`` the double-DQN target is the larger of the one-step target and the batch's
    return bound, for the same networks; without it the bounds are ignored; all goals are refused."""
    data = make_batch("dqn", tasks, size=16)
    data["return_bounds"] = np.where(np.arange(16) % 2 == 0, 0.9, 0.0).astype(np.float32)
    bounded, plain = build("dqn", tasks, return_bound=True), build("dqn", tasks)
    for agent in (plain, bounded):  # the same weights, away from zero
        agent.q.load_state_dict(build("dqn", tasks, seed=3).q.state_dict())
        agent.target.load_state_dict(agent.q.state_dict())
    with torch.no_grad():
        _, lifted = bounded._values(bounded.tensors(data))
        _, one_step = plain._values(plain.tensors(data))
    bounds = torch.as_tensor(data["return_bounds"])
    assert torch.equal(lifted, torch.maximum(one_step, bounds))
    assert (lifted > one_step).any() and torch.equal(lifted[bounds == 0], one_step[bounds == 0])
    with pytest.raises(ValueError, match="ReturnBounds extra"):
        bounded.update(make_batch("dqn", tasks))
    with pytest.raises(
        ValueError, match="return_bound_after=10 is a number of transitions, at least 0, and needs"
    ):
        build("dqn", tasks, return_bound_after=10)
    with pytest.raises(ValueError, match="return_bound bounds the sampled goal's target"):
        build("dqn", tasks, return_bound=True, all_goals=True)


def test_a_goal_difference_dqn_learns_its_goals_places(tasks):
    """``goal_difference``: the DQN's Q-network takes the goal through learnt places; an update moves the
    goals' places, which its state holds; a negative size, or one with goal heads, is refused."""
    agent = build("dqn", tasks, goal_difference=4)
    assert agent.q.difference is not None and agent.target.difference is not None
    places = agent.q.difference.goal_place.weight.detach().clone()
    assert all(np.isfinite(value) for value in agent.update(make_batch("dqn", tasks)).values())
    assert not torch.equal(places, agent.q.difference.goal_place.weight)
    assert "difference.goal_place.weight" in agent.q.state_dict()
    with pytest.raises(ValueError, match="goal_difference is a size: at least 0, got -1"):
        build("dqn", tasks, goal_difference=-1)
    with pytest.raises(ValueError, match="goal_difference and goal_heads each take the goal"):
        build("dqn", tasks, goal_difference=4, goal_heads=True)


def relabelled_to(data: dict[str, np.ndarray], goal: int) -> dict[str, np.ndarray]:
    """A batch with every transition's goal set to ``goal``, rewarded where it pressed that key."""
    size, goals = data["goals"].shape
    one_hot = np.tile(np.eye(goals, dtype=np.float32)[goal], (size, 1))
    return {**data, "goals": one_hot, "rewards": (data["achieved"] == goal).astype(np.float32)}


@pytest.mark.parametrize("goal_heads", [False, True])
def test_an_all_goals_update_is_the_single_goal_update_repeated_for_every_goal(tasks, goal_heads):
    """The all-goals targets under goal g are those of the batch relabelled to g, rewarded where
    its pressed key is g; and the loss averages every goal's squared error."""
    data = make_batch("dqn", tasks)
    goals = data["goals"].shape[1]
    data["achieved"] = np.array([-1, 0, 3, -1, 3, 5, -1, 1])  # some presses, some moves
    agent = build("dqn", tasks, all_goals=True, goal_heads=goal_heads)
    agent.target.load_state_dict(build("dqn", tasks, seed=1, goal_heads=goal_heads).q.state_dict())
    t = agent.tensors(data)
    with torch.no_grad():
        q_every, target_every = agent._all_goals_values(t)
        for g in range(goals):
            q, target = agent._values(agent.tensors(relabelled_to(data, g)))
            assert torch.allclose(q_every[:, g], q, atol=1e-6)
            assert torch.allclose(target_every[:, g], target, atol=1e-6)
    assert target_every[1, 0] > target_every[1, 1]  # the press of key 0 pays goal 0 only
    expected = 0.5 * ((q_every - target_every) ** 2).mean()
    assert agent.update(data)["losses/q_loss"] == pytest.approx(float(expected), rel=1e-5)


@pytest.mark.parametrize("goal_heads", [False, True])
def test_a_discrete_sac_all_goals_update_is_the_mean_of_its_single_goal_updates(tasks, goal_heads):
    """Discrete SAC under every goal: each goal's critic targets are those of the batch relabelled
    to it, and the critics', the actor's and the temperature's losses are the mean over goals of
    the single-goal updates' losses (each on a fresh copy of the same agent)."""
    data = make_batch("sac_discrete", tasks)
    goals = data["goals"].shape[1]
    data["achieved"] = np.array([-1, 0, 3, -1, 3, 5, -1, 1])
    other = build("sac_discrete", tasks, seed=1, goal_heads=goal_heads).critics.state_dict()

    def agent(**options):
        made = build("sac_discrete", tasks, goal_heads=goal_heads, **options)
        made.targets.load_state_dict(other)  # targets unlike the critics, so that they count
        return made

    every = agent(all_goals=True)
    alpha = every.log_alpha.exp().detach()
    with torch.no_grad():
        q_every, target_every = every._every_goal_values(every.tensors(data), alpha)
        for g in range(goals):
            q, target = every._values(every.tensors(relabelled_to(data, g)), alpha)
            assert all(torch.allclose(a[:, g], b, atol=1e-6) for a, b in zip(q_every, q, strict=True))
            assert torch.allclose(target_every[:, g], target, atol=1e-6)
    assert target_every[1, 0] > target_every[1, 1]  # the press of key 0 pays goal 0 only
    single = [agent().update(relabelled_to(data, g)) for g in range(goals)]
    losses = every.update(data)
    assert losses == pytest.approx({name: np.mean([s[name] for s in single]) for name in losses}, rel=1e-5)


def test_sacs_networks_give_every_goals_outputs_each_the_output_under_that_goal_alone(tasks):
    """SAC's critics value, and its policy acts, under every goal at once (the encoder run once): each
    goal's column is the output under that goal alone, for one action or one action per goal."""
    agent = build("sac", tasks, critic_pose=True, action_input_scale=3.0)
    data = make_batch("sac", tasks)
    images, goals, previous = state_inputs(agent, data)
    actions, poses = torch.as_tensor(data["actions"]), torch.rand(len(goals), 3)
    size = goals.shape[1]
    per_goal = torch.rand(len(goals), size, actions.shape[1]) * 2 - 1
    with torch.no_grad():
        every_sample, every_log_prob, every_mean = agent.actor.every_goal(images, previous)
        assert every_sample.shape == every_mean.shape and every_log_prob.shape == (len(goals), size)
        every_q = agent.critics[0].every_goal(images, previous, actions, poses)
        every_q_own = agent.critics[0].every_goal(images, previous, per_goal, poses)
        assert every_mean.shape == (len(goals), size, actions.shape[1])
        assert every_q.shape == (len(goals), size)
        for g in range(size):
            one_hot = torch.eye(size)[g].expand(len(goals), -1)
            assert torch.allclose(agent.actor(images, one_hot, previous)[2], every_mean[:, g], atol=1e-6)
            q = agent.critics[0](images, one_hot, previous, actions, poses)
            assert torch.allclose(q, every_q[:, g], atol=1e-5)
            own = agent.critics[0](images, one_hot, previous, per_goal[:, g], poses)
            assert torch.allclose(own, every_q_own[:, g], atol=1e-5)
    with pytest.raises(ValueError, match="needs poses of size 3"):
        agent.critics[0].every_goal(images, previous, actions)


def test_a_sac_all_goals_update_fits_each_goals_relabelled_targets(tasks):
    """SAC under every goal: its critics' and its actor's losses are the means over goals of the
    single-goal updates' on the batch relabelled to each goal (each on a fresh copy of the same
    agent; a policy of a vanishing deviation and temperature, so that the sampled actions agree,
    and critics left unmoved by their step, so that the actor meets the same critics)."""
    data = make_batch("sac", tasks)
    goals = data["goals"].shape[1]
    data["achieved"] = np.array([-1, 0, 3, -1, 3, 2, -1, 1])  # some presses, some moves
    other = build("sac", tasks, seed=1).critics.state_dict()

    def agent(**options):
        made = build("sac", tasks, log_std="tanh", initial_alpha=1e-9, **options)
        made.targets.load_state_dict(other)  # targets unlike the critics, so that they count
        with torch.no_grad():  # a log deviation of -20: the sampled action is the mean
            made.actor.log_std.weight.zero_()
            made.actor.log_std.bias.fill_(-50.0)
        made.critic_optimiser.step = lambda: None
        return made

    single = [agent().update(relabelled_to(data, g)) for g in range(goals)]
    every = agent(all_goals=True)
    actor = snapshot(every.actor)
    losses = every.update(data)
    for name in ("losses/qf_loss", "losses/actor_loss"):
        assert losses[name] == pytest.approx(np.mean([s[name] for s in single]), rel=1e-4), name
    assert not same_tensors(actor, snapshot(every.actor)) and all(np.isfinite(v) for v in losses.values())


def test_an_all_goals_update_needs_the_pressed_keys(tasks):
    for algo in ("dqn", "sac_discrete", "sac"):
        with pytest.raises(ValueError, match=r"'achieved'.*GoalOutcomes extra"):
            build(algo, tasks, all_goals=True).update(make_batch(algo, tasks))


def test_relabel_weights_weigh_each_goals_error_as_the_relabelling_samples_it(tasks):
    data = make_batch("dqn", tasks)
    goals = data["goals"].shape[1]
    data["achieved"] = np.array([-1, 0, 3, -1, 3, 5, -1, 1])
    rng = np.random.default_rng(0)
    data["goal_weights"] = rng.dirichlet(np.ones(goals), size=8).astype(np.float32)
    losses = {}
    for weights in ("uniform", "relabel"):
        agent = build("dqn", tasks, all_goals=True, all_goals_weights=weights)
        with torch.no_grad():
            q, target = agent._all_goals_values(agent.tensors(data))
        error = 0.5 * (q - target) ** 2
        expected = (
            error.mean()
            if weights == "uniform"
            else (error * torch.as_tensor(data["goal_weights"])).sum(-1).mean()
        )
        losses[weights] = agent.update(data)["losses/q_loss"]
        assert losses[weights] == pytest.approx(float(expected), rel=1e-5)
    assert losses["uniform"] != pytest.approx(losses["relabel"], rel=1e-3)


@pytest.mark.parametrize("algo", ["dqn", "sac_discrete"])
def test_all_goals_is_refused_with_n_step_returns_or_goal_positions(algo):
    from tactile_braille.agents.config import TrainConfig

    base = {"task": "tactile_braille/DiscreteAlphabet-v0", "algo": algo, "agent": {"all_goals": True}}
    assert TrainConfig(**base).agent.all_goals  # a tactile-track setting: the run is made
    with pytest.raises(ValueError, match=r"replay\.n_step=1"):
        TrainConfig(**base, replay={"n_step": 3})
    if algo == "dqn":  # discrete SAC weighs every goal alike
        with pytest.raises(ValueError, match=r"set agent\.all_goals"):
            TrainConfig(**{**base, "agent": {"all_goals_weights": "relabel"}})
    touch = {"enabled": True, "goal_positions": True}
    for name in ("all_goals", "goal_heads"):
        with pytest.raises(ValueError, match=rf"agent\.{name} reads the goal as a one-hot alone"):
            TrainConfig(**{**base, "agent": {name: True}}, track="proprio", touch=touch)
